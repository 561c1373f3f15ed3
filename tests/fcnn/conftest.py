from __future__ import annotations

import pytest
import torch

from graspnet_torch.robot import ChainKernel, UrdfModel

PLANAR_2R = """<robot name="planar"><link name="base"/><link name="l1"/><link name="l2"/><link name="tip"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
  <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/></joint>
<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.1 0 0"/><axis xyz="0 0 1"/>
  <limit lower="0.2" upper="2.4" effort="1" velocity="1"/></joint>
<joint name="jt" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.08 0 0"/></joint></robot>"""


@pytest.fixture(scope="session")
def planar_chain(tmp_path_factory):
    path = tmp_path_factory.mktemp("planar") / "planar.urdf"
    path.write_text(PLANAR_2R)
    return UrdfModel(path).chain_spec("base", "tip")


@pytest.fixture(scope="session")
def index_chain(hand):
    return hand.fingers["index"].chain.spec


@pytest.fixture(scope="session")
def index_kernel(index_chain):
    return ChainKernel(index_chain)


def limits(chain, dtype=torch.float32):
    return torch.tensor(chain.lower, dtype=dtype), torch.tensor(chain.upper, dtype=dtype)
