"""A robot's MuJoCo model (graspnet_torch/physics/model.py) compiled and set at a posture, for the
tests that compare its bodies with the package's forward kinematics."""

from __future__ import annotations

__all__ = ["posed_model"]


def posed_model(robot, obj, posture):
    """The compiled grasp model of ``robot`` holding ``obj`` (default protocol) with its joints at
    ``posture`` and ``mj_forward`` run: (model, data, the built model: its MJCF and start values)."""
    import mujoco

    from graspnet_torch.physics import PhysicsCfg
    from graspnet_torch.physics.model import grasp_mjcf

    built = grasp_mjcf(robot, obj, posture, posture, PhysicsCfg())
    model = mujoco.MjModel.from_xml_string(built.xml)
    data = mujoco.MjData(model)
    for name, value in built.start.items():
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_forward(model, data)
    return model, data, built
