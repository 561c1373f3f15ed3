"""An object in, grasps out: the best grasps of each mesh in a folder, with a summary table.

    python scripts/synthesize_grasps.py objects=FOLDER robot=hand
    python scripts/synthesize_grasps.py objects=mug.stl scale=0.001 grasps=3 verify=none out=results/
    python scripts/synthesize_grasps.py -m hydra/launcher=joblib objects=FOLDER seed=0,1,2

Writes ``<out>/<object>.json`` per mesh (contacts, quality, the solve, the physics check) and
``<out>/summary.csv`` (``out`` defaults to ``<run dir>/results``); an object whose result exists is
skipped, so a stopped run resumes. A mesh that cannot be read, or where no grasp is found, is
recorded with its reason.

Exit status: 0 when it ran, 2 when the input was refused (one line on stderr, nothing written),
1 for anything else.
"""

from __future__ import annotations

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from graspnet_torch.jobs.cli import container, run_cli, user_errors_exit_2
from graspnet_torch.jobs.synthesize import SynthesizeGraspsJobCfg, prepare_synthesize, synthesize_objects


@hydra.main(config_path="../configs", config_name="synthesize_grasps", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    synthesize_objects(*prepare_synthesize(container(cfg), HydraConfig.get().runtime.output_dir))


if __name__ == "__main__":
    run_cli(main, SynthesizeGraspsJobCfg, config_name="synthesize_grasps", prepare=prepare_synthesize)
