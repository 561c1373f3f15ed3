"""Is a problem reachable? Fit a posture that puts each fingertip on its contact (least squares).

    python scripts/reference_posture.py task=videotape5
    python scripts/reference_posture.py problem=my_problem.yaml restarts=48
"""

from __future__ import annotations

import sys

import hydra
from omegaconf import DictConfig, OmegaConf

from graspnet_torch.jobs.cli import check_group_overrides, user_errors_exit_2
from graspnet_torch.jobs.reference_posture import reference_posture


@hydra.main(config_path="../configs", config_name="reference_posture", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    reference_posture(OmegaConf.to_container(cfg, resolve=True))


if __name__ == "__main__":
    check_group_overrides(sys.argv[1:], ("task",))
    main()
