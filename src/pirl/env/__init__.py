"""The VCPP environments: single (Gymnasium) and batched (Stable-Baselines3 VecEnv)."""

from pirl.env.vcpp_env import VCPPEnv
from pirl.env.vec_env import VCPPVecEnv, make_vec_env

__all__ = ["VCPPEnv", "VCPPVecEnv", "make_vec_env"]
