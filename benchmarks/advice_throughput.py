"""Advice throughput: the embedded LLM, and what PARE costs the vectorized environment.

Prints, in one run:

1. local advisor prompts/s answering one prompt at a time vs in batches;
2. env-steps/s of the PARE-wrapped ``make_vec_env`` with the local advisor in sync mode for
   K = 1, 8, 32 (cache cold, then warm on the same states) and in async mode, against the
   unwrapped vec env stepping the same random actions;
3. LLM calls per env-step, parse rate and cache hit rate of each case.

Usage: ``python benchmarks/advice_throughput.py [--envs 16] [--threads 1] [--seconds 20]``.
The sync cases run a fixed number of steps (fewer for small K, since each waits for the LLM).

``--prefix-reuse`` measures instead the embedded teacher's answers per second with and
without the reuse of the shared prompt prefix's key/value cache (``LocalAdvisor
(prefix_reuse=...)``), in one run, alternating the two on the same prompts (states of
training rollouts, batches of ``--batch``): first on one core alone, then beside
``--workers`` PPO training processes (the demo's conditions). It prints parse rate and answer
distribution of both and ends with ``prefix reuse: A answers/s, without: B answers/s,
speed-up C.Cx`` (the figures beside the workers when there are any).

``--against REV`` measures instead the embedded teacher of this code against the one of git
revision ``REV`` (its ``src`` exported to a temporary folder), each in child processes that
alternate on the same prompts (states of training rollouts, ``--prompts`` of them per
``--variants`` entry, batches of ``--batch``, ``--rounds`` passes each, ``--dtype``): answers
per second of each, and the share of identical answer texts. It ends with ``this code: A
answers/s, REV: B answers/s, ratio C.CCx``.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from pirl.advice.cache import CachedAdvisor
from pirl.advice.local import LocalAdvisor
from pirl.advice.model_store import default_dtype
from pirl.advice.prompt import build_prompt
from pirl.advice.state import prompt_state
from pirl.config.run import PareSettings
from pirl.env import make_vec_env
from pirl.pare.bundle import AdviceBundle
from pirl.pare.sb3_vec import PAREVecEnv

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
    settings = PareSettings(mode=mode, query_every=k)
    advice = AdviceBundle(advisor, None, None, 0.0, 16, "")
    pare = PAREVecEnv.from_settings(make_vec_env(envs, seed=0, **SETTINGS), settings, advice)
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
    pare.pare.source.reset()  # waits for the batch in flight; the advisor serves the next case
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


def rollout_prompts(n: int, variant: str, seed: int = 7) -> list[str]:
    """Prompts about ``n`` states met along random rollouts of the training world (distinct
    positions, cameras, batteries and obstacles, as the teacher queue samples them)."""
    venv = make_vec_env(n, seed=seed, **SETTINGS)
    venv.reset()
    rng = np.random.default_rng(seed)
    for _ in range(int(rng.integers(5, 40))):
        venv.step(rng.integers(0, 12, n))
    return [build_prompt(prompt_state(venv.world, e), variant) for e in range(n)]


def _train_forever(out: str, seed: int) -> None:
    """A PPO-EWRI training worker at the quick profile's settings (one torch thread), as
    ``pirl reproduce`` runs two beside the teacher."""
    import torch

    from pirl.agents.train import train
    from pirl.config.run import RunConfig

    torch.set_num_threads(1)
    root = Path(__file__).resolve().parents[1]
    cfg = RunConfig.from_yaml(root / "configs" / "quick.yaml")
    cfg = cfg.with_overrides(train={"total_steps": 50_000_000, "checkpoint_every": 10**9})
    train("ppo-ewri", cfg, Path(out) / f"w{seed}", seed=seed, show_progress=False)


def _common_length(rows: list[list[int]]) -> int:
    """Length of the token prefix all ``rows`` share."""
    first, n = rows[0], min(len(r) for r in rows)
    for i in range(n):
        if any(r[i] != first[i] for r in rows):
            return i
    return n


# Runs in a child process on either revision's code: only LocalAdvisor's public API.
_DECODER_CHILD = """
import json, sys, time
from pirl.advice.local import LocalAdvisor
job = json.load(open(sys.argv[1]))
llm = LocalAdvisor(num_threads=job["threads"], batch_size=job["batch"], dtype=job["dtype"])
prompts = job["prompts"]
llm.advise(prompts[: job["batch"]])  # warm-up: first calls are slower
start = time.perf_counter()
answers = llm.advise(prompts)
seconds = time.perf_counter() - start
print(json.dumps({"seconds": seconds, "texts": [a.text for a in answers],
                  "parsed": sum(a.recommendation is not None for a in answers)}))
"""


def _decoder_run(src: str, job_file: str) -> dict:
    """One child process of the code in ``src`` answering the prompts of ``job_file``."""
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=src, PYTHONWARNINGS="ignore")
    out = subprocess.run(
        [sys.executable, "-c", _DECODER_CHILD, job_file],
        capture_output=True, text=True, env=env, cwd=root, check=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def against_main(args: argparse.Namespace) -> None:
    """This code's embedded teacher against revision ``args.against``'s, alternating."""
    root = Path(__file__).resolve().parents[1]
    dtype = args.dtype or default_dtype("cpu")
    with tempfile.TemporaryDirectory(prefix="pirl-old-") as folder:
        archive = subprocess.run(
            ["git", "archive", args.against, "src"], cwd=root, capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
        codes = {"this code": str(root / "src"), args.against: str(Path(folder) / "src")}
        prompts = [p for v in args.variants for p in rollout_prompts(args.prompts, v)]
        job = {"threads": args.threads, "batch": args.batch, "dtype": dtype, "prompts": prompts}
        job_file = Path(folder) / "job.json"
        job_file.write_text(json.dumps(job))
        seconds = dict.fromkeys(codes, 0.0)
        texts: dict[str, list[str]] = {c: [] for c in codes}
        parsed = dict.fromkeys(codes, 0)
        for r in range(args.rounds):
            order = list(codes) if r % 2 == 0 else list(codes)[::-1]  # the load drifts
            for code in order:
                got = _decoder_run(codes[code], str(job_file))
                seconds[code] += got["seconds"]
                texts[code] += got["texts"]
                parsed[code] += got["parsed"]
    n = len(prompts) * args.rounds
    print(
        f"embedded teacher, {len(prompts)} prompts ({', '.join(args.variants)}) x "
        f"{args.rounds} rounds, batches of {args.batch}, {dtype}, {args.threads} thread(s)"
    )
    for code in codes:
        answers = Counter(texts[code])
        top = ", ".join(f"{k}x '{t}'" for t, k in answers.most_common(2))
        print(
            f"  {code:<10} {n / seconds[code]:.2f} answers/s, parse rate {parsed[code] / n:.0%}, "
            f"{len(answers)} distinct answers; most frequent: {top}"
        )
    this, old = codes
    same = sum(a == b for a, b in zip(texts[this], texts[old], strict=True))
    print(f"  same answer text: {same / n:.0%} of {n}")
    a, b = n / seconds[this], n / seconds[old]
    print(f"this code: {a:.2f} answers/s, {old}: {b:.2f} answers/s, ratio {a / b:.2f}x")


def prefix_rates(llm: LocalAdvisor, prompts: list[str], batch: int, rounds: int) -> dict:
    """Answers/s with and without prefix reuse, alternating per batch on the same prompts."""
    modes = {
        "with": llm.with_settings(batch_size=batch),
        "without": llm.with_settings(batch_size=batch),
    }
    modes["with"].prefix_reuse, modes["without"].prefix_reuse = True, False
    seconds = dict.fromkeys(modes, 0.0)
    answers: dict[str, list] = {m: [] for m in modes}
    for r in range(rounds):
        for start in range(0, len(prompts), batch):
            chunk = prompts[start : start + batch]
            order = ("with", "without") if (r + start // batch) % 2 == 0 else ("without", "with")
            for mode in order:  # alternate which goes first: the load drifts
                t = time.perf_counter()
                answers[mode] += modes[mode].advise(chunk)
                seconds[mode] += time.perf_counter() - t
    out = {}
    for mode, got in answers.items():
        parsed = [a for a in got if a.recommendation is not None]
        out[mode] = {
            "rate": len(got) / seconds[mode],
            "parse": len(parsed) / len(got),
            "answers": Counter(a.text for a in got),
            "texts": [a.text for a in got],
        }
    same = sum(a == b for a, b in zip(out["with"]["texts"], out["without"]["texts"], strict=True))
    out["same"] = same / len(out["with"]["texts"])
    return out


def _print_prefix(title: str, r: dict, n_prompt: int) -> None:
    print(f"\n{title}")
    for mode in ("with", "without"):
        m = r[mode]
        top = ", ".join(f"{n}x '{t}'" for t, n in m["answers"].most_common(3))
        print(
            f"  {mode:<7} prefix reuse: {m['rate']:.2f} answers/s, parse rate {m['parse']:.0%}, "
            f"{len(m['answers'])} distinct answers; most frequent: {top}"
        )
    print(f"  same answer text with and without: {r['same']:.0%} of {n_prompt} prompts")


def prefix_main(args: argparse.Namespace) -> None:
    llm = LocalAdvisor(num_threads=args.threads, batch_size=args.batch)
    rows: list[tuple[str, dict]] = []
    for variant in args.variants:
        prompts = rollout_prompts(args.prompts, variant)
        ids = [llm.tokenizer(llm.chat_text(p), add_special_tokens=False)["input_ids"]
               for p in prompts]  # fmt: skip
        tokens, shared = [len(i) for i in ids], _common_length(ids)
        llm.advise(prompts[: args.batch])  # warm-up: first calls are slower
        r = prefix_rates(llm, prompts, args.batch, args.rounds)
        _print_prefix(
            f"{variant} prompt, {len(prompts)} states x {args.rounds} rounds, batches of "
            f"{args.batch}, one core alone ({np.mean(tokens):.0f} tokens per prompt, "
            f"{shared} shared)",
            r,
            len(r["with"]["texts"]),
        )
        rows.append((f"{variant}, alone", r))
    if args.workers:
        ctx = mp.get_context("spawn")
        with tempfile.TemporaryDirectory() as tmp:
            procs = [
                ctx.Process(target=_train_forever, args=(tmp, s), daemon=True)
                for s in range(args.workers)
            ]
            for p in procs:
                p.start()
            time.sleep(args.warmup)  # imports and numba compilation, then steady training
            try:
                prompts = rollout_prompts(args.prompts, args.variants[0])
                r = prefix_rates(llm, prompts, args.batch, args.rounds)
                _print_prefix(
                    f"{args.variants[0]} prompt beside {args.workers} PPO training workers",
                    r,
                    len(r["with"]["texts"]),
                )
                rows.append((f"{args.variants[0]}, beside {args.workers} workers", r))
            finally:
                for p in procs:
                    p.terminate()
                for p in procs:
                    p.join(10)
    name, last = rows[-1]
    a, b = last["with"]["rate"], last["without"]["rate"]
    print(f"({name})")
    print(f"prefix reuse: {a:.2f} answers/s, without: {b:.2f} answers/s, speed-up {a / b:.1f}x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--threads", type=int, default=1, help="LLM CPU threads")
    parser.add_argument("--seconds", type=float, default=20.0, help="async case duration")
    parser.add_argument("--prefix-reuse", action="store_true", help="measure prefix reuse")
    parser.add_argument("--prompts", type=int, default=32, help="--prefix-reuse: states")
    parser.add_argument("--batch", type=int, default=16, help="--prefix-reuse: batch size")
    parser.add_argument("--rounds", type=int, default=1, help="--prefix-reuse: passes")
    parser.add_argument("--workers", type=int, default=2, help="--prefix-reuse: PPO workers")
    parser.add_argument("--warmup", type=float, default=25.0, help="s before measuring")
    parser.add_argument(
        "--variants", nargs="+", default=["compact", "paper"], help="--prefix-reuse: prompts"
    )
    parser.add_argument("--against", metavar="REV", help="measure the teacher against REV")
    parser.add_argument("--dtype", default=None, help="--against: torch dtype of both")
    args = parser.parse_args()
    if args.against:
        against_main(args)
        return
    if args.prefix_reuse:
        prefix_main(args)
        return
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
