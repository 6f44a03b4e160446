"""PARE, the Prompt-Adaptive Reward Engine: a pure core (:mod:`pirl.pare.core`, the alignment
terms of :mod:`pirl.pare.alignment`), advice sources (:mod:`pirl.pare.sources`: student, sync,
async), the engine that joins them (:mod:`pirl.pare.engine`) and thin adapters for
Stable-Baselines3 (:mod:`pirl.pare.sb3_vec`) and Gymnasium (:mod:`pirl.pare.gym_vector`)."""

from pirl.pare.alignment import alignment, alignment_arrays, f_llm

__all__ = ["PAREVecEnv", "alignment", "alignment_arrays", "f_llm"]


def __getattr__(name: str):
    # The wrapper pulls in Stable-Baselines3; import it only when asked for.
    if name == "PAREVecEnv":
        from pirl.pare.sb3_vec import PAREVecEnv

        return PAREVecEnv
    raise AttributeError(name)
