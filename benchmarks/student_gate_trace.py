"""When does the student's gate open, and does it stay open? The gate's rule chosen on
validation states, without training PPO.

For each teacher (the oracle at several accuracies) it asks about distillation states
(planner and random rollouts on scenario seeds from 2,000,000 + 100,000 * seed: neither
training's nor evaluation's), then replays a PIRL run's student schedule on them: at each of
the run's rollout boundaries the answers of one rollout arrive (``--rate`` answers per step,
``--rollout`` steps per rollout), the student is refit as PIRL refits it
(:class:`pirl.pare.sources.student.StudentSource`: warm and fresh while the gate is closed,
warm once the answers grew by ``pare.student_refit_growth`` while it is open) and each
candidate gate rule decides whether the next rollout is shaped. It prints, per teacher and
rule, the share of the run's steps the gate had open, when it first opened and how often it
closed again. Every rule replays on the same answers.

    .venv/bin/python benchmarks/student_gate_trace.py [--seeds 7 8] [--accuracies 1,0.75,0.5]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

RULES = {
    # name: (pare.student_gate_on, opens at >=, closes below, fewest held-out answers)
    "kappa 0.10, no hysteresis": ("kappa", 0.10, 0.10, 20),
    "kappa 0.10, closes below 0.05": ("kappa", 0.10, 0.05, 20),
    "kappa 0.05, closes below 0.025": ("kappa", 0.05, 0.025, 20),
    "move kappa 0.10, closes below 0.05": ("move_kappa", 0.10, 0.05, 20),
    "best field kappa 0.10, closes below 0.05": ("best_kappa", 0.10, 0.05, 20),
    "best field kappa 0.15, closes below 0.075": ("best_kappa", 0.15, 0.075, 20),
    "best field kappa 0.20, closes below 0.10": ("best_kappa", 0.20, 0.10, 20),
    "kappa - 3 SE >= 0.02, closes below 0.01": ("kappa_lcb", 0.02, 0.01, 20),
    "kappa - 3 SE >= 0.0, closes below -0.05": ("kappa_lcb", 0.0, -0.05, 20),
}


def replay(
    x: np.ndarray,
    y: np.ndarray,
    rule: tuple,
    args: argparse.Namespace,
    arrive: np.ndarray | None = None,
) -> tuple[float, int, int]:
    """(share of steps open, first step open or -1, closings) of one rule on one stream.
    ``arrive``: the boundary at which each row arrives (a recorded run's); else an even
    ``--rate``."""
    from pirl.advice.student import Student, gate_value

    on, gate, close, min_held = rule
    student = Student("trace", x.shape[1], hidden=args.hidden, seed=0)
    per = max(1, round(args.rate * args.rollout))
    boundaries = args.steps // args.rollout
    if arrive is None:
        arrive = np.arange(len(x)) // per
    is_open, open_rollouts, first, closings = False, 0, -1, 0
    for b in range(boundaries):
        rows = np.flatnonzero(arrive == b)
        if len(rows):
            student.add(rows + 1, x[rows], y[rows])
        new = student.dataset_size - student.fitted_rows
        if new > 0 and not is_open:
            student.fit_closed(args.fit_steps, "kappa")
        elif new > 0 and new >= args.growth * student.fitted_rows:
            student.fit(args.fit_steps)
        enough = student.score.heldout >= min_held
        was = is_open
        is_open = enough and gate_value(student.score, on) >= (close if was else gate)
        closings += int(was and not is_open)
        if is_open and first < 0:
            first = (b + 1) * args.rollout
        open_rollouts += int(is_open)
    return open_rollouts / boundaries, first, closings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--accuracies", default="1.0,0.75,0.5,0.25,0.0")
    parser.add_argument("--seeds", type=int, nargs="+", default=[7, 8])
    parser.add_argument("--config", default="study-advice")
    parser.add_argument("--steps", type=int, default=262_144, help="the run's PPO steps")
    parser.add_argument("--rollout", type=int, default=4096, help="steps per rollout")
    parser.add_argument("--rate", type=float, default=0.02, help="teacher answers per step")
    parser.add_argument("--fit-steps", type=int, default=100)
    parser.add_argument("--growth", type=float, default=0.25)
    parser.add_argument("--hidden", type=int, default=128)
    parser.add_argument(
        "--dataset",
        default="",
        help="replay the answers recorded by the runs of a study instead (its student.sqlite; "
        "runs with student_dataset_scope: run), in the order and at the steps they arrived",
    )
    parser.add_argument("--replay-seeds", type=int, nargs="*", default=[])
    parser.add_argument("--rules", default="", help="comma-separated rule numbers (1-based)")
    args = parser.parse_args()
    args.replay_accuracies = {float(a) for a in args.accuracies.split(",")}
    if args.rules:
        keep = {int(k) - 1 for k in args.rules.split(",")}
        for k, name in enumerate(list(RULES)):
            if k not in keep:
                del RULES[name]
    import torch

    torch.set_num_threads(1)
    if args.dataset:
        replay_dataset(args)
        return
    os.environ.setdefault("PIRL_CACHE_DIR", tempfile.mkdtemp(prefix="pirl-gate-trace-"))

    import torch

    torch.set_num_threads(1)
    from pirl.advice.oracle import OracleAdvisor
    from pirl.advice.student import encode
    from pirl.agents.distill import collect_states
    from pirl.config.presets import preset_path as _preset
    from pirl.config.run import RunConfig

    cfg = RunConfig.from_yaml(_preset(args.config, "--config"))
    need = int(args.rate * args.steps) + 1
    print(f"{need} answers per stream ({args.steps:,} steps at {args.rate} answers per step), "
          f"refit every {args.rollout} steps with {args.fit_steps} Adam steps")  # fmt: skip
    results: dict[tuple[float, str], list[tuple[float, int, int]]] = {}
    for seed in args.seeds:
        for acc in (float(a) for a in args.accuracies.split(",")):
            began = time.perf_counter()
            advisor = OracleAdvisor(acc)
            prompts, views, x = collect_states(
                cfg, advisor, ("boustrophedon", "random"), need, seed=seed
            )
            answers = advisor.advise(prompts, views)
            keep = [i for i, a in enumerate(answers) if a.recommendation is not None]
            y = encode([answers[i].recommendation for i in keep])
            x = x[keep]
            # A run's answers come from its own rollouts in time order; shuffle so that one
            # boundary's answers are not all from one episode.
            order = np.random.default_rng(seed).permutation(len(x))
            x, y = x[order], y[order]
            for name, rule in RULES.items():
                results.setdefault((acc, name), []).append(replay(x, y, rule, args))
            print(f"seed {seed}, accuracy {acc:g}: {time.perf_counter() - began:.0f} s", flush=True)
    print("\n| teacher | rule | open share per seed | first open (step) | closings |")
    print("|---|---|---|---|---|")
    for (acc, name), rows in results.items():
        shares = " / ".join(f"{r[0]:.0%}" for r in rows)
        firsts = " / ".join(f"{r[1]:,}" if r[1] >= 0 else "never" for r in rows)
        closings = " / ".join(str(r[2]) for r in rows)
        print(f"| oracle, accuracy {acc:g} | {name} | {shares} | {firsts} | {closings} |")


def replay_dataset(args: argparse.Namespace) -> None:
    """Each recorded run's answers, replayed under every rule."""
    import json
    import re
    import sqlite3

    db = sqlite3.connect(f"file:{args.dataset}?mode=ro", uri=True)
    sources = [r[0] for r in db.execute("SELECT DISTINCT source FROM samples")]
    results: dict[tuple[str, str], list[tuple[float, int, int]]] = {}
    per_boundary = args.rollout // 16  # the board counts vector steps (16 worlds)
    for source in sorted(sources):
        found = re.search(r"acc(?:uracy)?([0-9.]+)-.*s(\d+)$", source)
        if not found or float(found.group(1)) not in args.replay_accuracies:
            continue
        if args.replay_seeds and int(found.group(2)) not in args.replay_seeds:
            continue
        rows = db.execute(
            "SELECT features, labels, t FROM samples WHERE source = ? ORDER BY id", (source,)
        ).fetchall()
        x = np.stack([np.frombuffer(r[0], dtype=np.float32) for r in rows])
        y = np.array([json.loads(r[1]) for r in rows], dtype=np.int64)
        arrive = np.array([(r[2] - 1) // per_boundary for r in rows])
        for name, rule in RULES.items():
            results.setdefault((found.group(1), name), []).append(replay(x, y, rule, args, arrive))
        print(f"replayed {source}", flush=True)
    print("\n| teacher | rule | open share per seed | first open (step) | closings |")
    print("|---|---|---|---|---|")
    for (acc, name), rs in sorted(results.items(), key=lambda kv: -float(kv[0][0])):
        shares = " / ".join(f"{r[0]:.0%}" for r in rs)
        firsts = " / ".join(f"{r[1]:,}" if r[1] >= 0 else "never" for r in rs)
        print(f"| oracle, accuracy {acc} | {name} | {shares} | {firsts} | "
              f"{' / '.join(str(r[2]) for r in rs)} |")  # fmt: skip


if __name__ == "__main__":
    main()
