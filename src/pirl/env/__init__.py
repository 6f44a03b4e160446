"""The VCPP environments: single (Gymnasium), batched as a Gymnasium vector env and as a
Stable-Baselines3 VecEnv; all three run the same :class:`~pirl.env.core.EnvCore`."""

from pirl.env.vcpp_env import VCPPEnv
from pirl.env.vec_env import VCPPVecEnv, make_vec_env
from pirl.env.vector import VCPPVectorEnv

__all__ = ["VCPPEnv", "VCPPVecEnv", "VCPPVectorEnv", "make_vec_env"]
