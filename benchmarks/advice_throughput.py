"""Advice throughput: the embedded LLM, and what PARE costs the vectorized environment.

Prints, in one run:

1. local advisor prompts/s answering one prompt at a time vs in batches;
2. env-steps/s of the PARE-wrapped ``make_vec_env`` with the local advisor in sync mode for
   K = 1, 8, 32 (cache cold, then warm on the same states) and in async mode, against the
   unwrapped vec env stepping the same random actions;
3. LLM calls per env-step, parse rate and cache hit rate of each case.

Usage: ``python benchmarks/advice_throughput.py [--envs 16] [--threads 1] [--seconds 20]``.
The sync cases run a fixed number of steps (fewer for small K, since each waits for the LLM).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from pirl.advice.cache import CachedAdvisor
from pirl.advice.local import LocalAdvisor
from pirl.advice.prompt import build_prompt
from pirl.advice.state import prompt_state
from pirl.env import make_vec_env
from pirl.pare.wrapper import PAREVecEnv

SETTINGS = {"size": (15, 15, 3), "reward": "ewri", "llm_weight": True}


def prompts_for(n: int) -> list[str]:
    venv = make_vec_env(n, seed=123, **SETTINGS)
    venv.reset()
    return [build_prompt(prompt_state(venv.world, e)) for e in range(n)]


def llm_rates(llm: LocalAdvisor, n: int) -> tuple[float, float]:
    prompts = prompts_for(n)
    start = time.perf_counter()
    for p in prompts:
        llm.advise([p])
    single = n / (time.perf_counter() - start)
    start = time.perf_counter()
    llm.advise(prompts)
    return single, n / (time.perf_counter() - start)


def unwrapped_rate(envs: int, steps: int) -> float:
    venv = make_vec_env(envs, seed=0, **SETTINGS)
    venv.reset()
    actions = np.random.default_rng(0).integers(0, 12, (steps, envs))
    start = time.perf_counter()
    for a in actions:
        venv.step(a)
    return steps * envs / (time.perf_counter() - start)


def pare_case(advisor, envs: int, mode: str, k: int, steps: int | None, seconds: float) -> dict:
    pare = PAREVecEnv(make_vec_env(envs, seed=0, **SETTINGS), advisor, query_every=k, mode=mode)
    pare.reset()
    actions = np.random.default_rng(0).integers(0, 12, (100_000, envs))
    hits0 = getattr(advisor, "hits", 0)
    misses0 = getattr(advisor, "misses", 0)
    start, n = time.perf_counter(), 0
    while (steps is not None and n < steps) or (
        steps is None and time.perf_counter() - start < seconds
    ):
        pare.step(actions[n])
        n += 1
    elapsed = time.perf_counter() - start
    stats = pare.stats.as_dict()
    pare._drain()
    hits = getattr(advisor, "hits", 0) - hits0
    misses = getattr(advisor, "misses", 0) - misses0
    return {
        "sps": n * envs / elapsed,
        "calls_per_step": stats["prompts_sent"] / (n * envs),
        "parse": stats["parse_rate"],
        "hit_rate": hits / (hits + misses) if hits + misses else 0.0,
        "stale": stats["mean_staleness"],
        "shaped": 1 - stats["steps_missing"] / max(1, stats["steps"]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--threads", type=int, default=1, help="LLM CPU threads")
    parser.add_argument("--seconds", type=float, default=20.0, help="async case duration")
    args = parser.parse_args()
    llm = LocalAdvisor(num_threads=args.threads, batch_size=32)
    for batch in (8, 32):
        single, batched = llm_rates(llm, batch)
        print(
            f"local advisor ({llm.model}), {batch} prompts: one at a time {single:.2f} "
            f"prompts/s, one batch {batched:.2f} prompts/s ({batched / single:.1f}x)"
        )

    base = unwrapped_rate(args.envs, 3000)
    print(f"\nPARE-wrapped make_vec_env({args.envs}), 15x15x3, random actions")
    print(f"unwrapped vec env: {base:,.0f} env-steps/s")
    head = f"{'case':<26} {'env-steps/s':>12} {'vs plain':>9} {'calls/step':>11}"
    print(head + f" {'parse':>6} {'cache hits':>10} {'shaped':>7} {'staleness':>9}")
    with tempfile.TemporaryDirectory() as tmp:
        cache_path = Path(tmp) / "advice.sqlite"
        for k, steps in ((1, 3), (8, 16), (32, 64)):
            for temp in ("cold", "warm"):
                advisor = CachedAdvisor(llm, cache_path)
                r = pare_case(advisor, args.envs, "sync", k, steps, 0)
                _row(f"sync K={k} cache {temp}", r, base)
        advisor = CachedAdvisor(llm, Path(tmp) / "async.sqlite")
        r = pare_case(advisor, args.envs, "async", 1, None, args.seconds)
        _row(f"async K=1 ({args.seconds:.0f} s)", r, base)


def _row(name: str, r: dict, base: float) -> None:
    print(
        f"{name:<26} {r['sps']:>12,.0f} {r['sps'] / base:>9.1%} {r['calls_per_step']:>11.3f} "
        f"{r['parse']:>6.0%} {r['hit_rate']:>10.0%} {r['shaped']:>7.0%} {r['stale']:>9.1f}"
    )


if __name__ == "__main__":
    main()
