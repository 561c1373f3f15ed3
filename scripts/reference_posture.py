"""Is a problem reachable? Fit a posture that puts each fingertip on its contact (least squares).

    python scripts/reference_posture.py task=videotape5
    python scripts/reference_posture.py problem=my_problem.yaml restarts=48
"""

from __future__ import annotations

import hydra
from omegaconf import DictConfig

from graspnet_torch.jobs.cli import container, run_cli, user_errors_exit_2
from graspnet_torch.jobs.configs import ReferencePostureJobCfg
from graspnet_torch.jobs.reference_posture import prepare_reference, reference_posture


@hydra.main(config_path="../configs", config_name="reference_posture", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    reference_posture(container(cfg))


if __name__ == "__main__":
    run_cli(main, ReferencePostureJobCfg, config_name="reference_posture", prepare=prepare_reference)
