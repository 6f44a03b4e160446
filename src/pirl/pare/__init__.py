"""PARE, the Prompt-Adaptive Reward Engine: alignment terms and the training wrapper."""

from pirl.pare.alignment import alignment, alignment_arrays, f_llm

__all__ = ["PAREVecEnv", "alignment", "alignment_arrays", "f_llm"]


def __getattr__(name: str):
    # The wrapper pulls in Stable-Baselines3; import it only when asked for.
    if name == "PAREVecEnv":
        from pirl.pare.wrapper import PAREVecEnv

        return PAREVecEnv
    raise AttributeError(name)
