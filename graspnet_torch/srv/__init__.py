"""SRV units and the generic configuration network (paper section 4)."""

from graspnet_torch.srv.function import SigmaCfg, SRVFunction, sigma_of
from graspnet_torch.srv.network import ConfigurationNetwork, SRVNetCfg, SRVStep

__all__ = ["ConfigurationNetwork", "SRVFunction", "SRVNetCfg", "SRVStep", "SigmaCfg", "sigma_of"]
