"""Environment throughput: agent-steps per second with random actions, batched against naive.

All rows are measured in the same run, on the same machine, so their ratios are meaningful
even where the absolute numbers are noisy (a shared machine):

- ``naive``: one world, the same rule code run as plain Python over numpy arrays (numba's JIT
  disabled, in a subprocess), stepped in a Python loop: what the env would be without the
  compiled kernels.
- ``single``: one compiled ``VCPPEnv`` stepped in a Python loop (the Gymnasium API per step).
- ``SyncVectorEnv``: Gymnasium's Python loop over single envs, what ``make_vec`` gave before
  the vector entry point.
- ``VCPPVectorEnv``: ``gym.make_vec("pirl/VCPP-v0", num_envs=N)``, the Gymnasium vector env.
- ``VCPPVecEnv``: ``make_vec_env(N)``, the Stable-Baselines3 adapter (per-world info dicts).
- ``EnvCore``: the batched core alone (one kernel call per step, no API around it).

``--against REV`` adds the batched rows of the code at git revision ``REV`` (its ``src``
exported to a temporary folder and measured in a child process, interleaved with this code's
rows, best of two each): the same run measures a change against the code before it.

``--site PATH`` measures the batched rows on a site (docs/sites.md) against ``--size`` in the
same run (interleaved, best of two) and states the memory of one world of each.

``--baseline-settings JSON`` measures the same batched rows with other env settings, as a
ratio (e.g. an observation option on against off).

``--uavs 1,4,8`` measures fleets (docs/fleets.md): UAV-steps per second of the SB3 fleet
VecEnv (``make_fleet_vec_env``, a slot per UAV) and of the batched core with K UAVs per
world, on ``--size`` and on ``--site`` when given, with about ``--envs`` UAVs in all (``envs
// K`` worlds), interleaved and best of two, as a ratio of K = 1 measured in the same run.

Usage: ``python benchmarks/env_throughput.py [--seconds 2] [--envs 64] [--size 60x60x3]
[--footprint paper] [--threads] [--against REV] [--settings JSON] [--baseline-settings
JSON]``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import pirl  # noqa: F401  (registers pirl/VCPP-v0)
from pirl.config.world import VCPPConfig
from pirl.env import VCPPEnv, VCPPVectorEnv, make_vec_env
from pirl.env.core import EnvCore


def rate(step: Callable[[int], object], per_call: int, seconds: float) -> float:
    """Agent-steps per second of ``step(k)`` (k counts calls), best of three slices."""
    step(0)  # compile and warm up outside the timed loop
    best, calls = 0.0, 1
    for _ in range(3):
        n, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < seconds / 3:
            for _ in range(20):
                step(calls)
                calls += 1
            n += 20
        best = max(best, n * per_call / elapsed)
    return best


def single_rate(settings: dict, seconds: float) -> float:
    env = VCPPEnv(**settings)
    env.reset(seed=0)
    actions = np.random.default_rng(0).integers(0, 12, 4096).tolist()

    def step(k: int) -> None:
        _, _, terminated, truncated, _ = env.step(actions[k % 4096])
        if terminated or truncated:
            env.reset()

    return rate(step, 1, seconds)


def batched_rate(env_step: Callable[[np.ndarray], object], envs: int, seconds: float) -> float:
    actions = np.random.default_rng(0).integers(0, 12, (256, envs))
    return rate(lambda k: env_step(actions[k % 256]), envs, seconds)


def naive_rate(settings: dict, seconds: float) -> float:
    """The single env with numba's JIT off, measured in a child process (the flag is global)."""
    code = (
        "import json, sys; sys.path.insert(0, 'benchmarks');"
        "from env_throughput import single_rate;"
        f"print(single_rate(json.loads(sys.argv[1]), {seconds}))"
    )
    import json

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONWARNINGS="ignore")
    out = subprocess.run(
        [sys.executable, "-c", code, json.dumps(settings)],
        capture_output=True, text=True, env=env, cwd=root, check=True,
    )  # fmt: skip
    return float(out.stdout.strip().splitlines()[-1])


def core_rates(settings: dict, envs: int, seconds: float) -> dict[str, float]:
    """Agent-steps/s of the SB3 adapter and of the batched core (the rows --against compares)."""
    if settings.get("site"):  # only this code has sites: an older revision never gets one
        from pirl.world.seeable import with_site

        plain = {k: v for k, v in settings.items() if k != "site"}
        cfg = with_site(VCPPConfig(**{**plain, "size": tuple(plain["size"])}), settings["site"])
    else:
        cfg = VCPPConfig(**{**settings, "size": tuple(settings["size"])})
    sb3 = make_vec_env(envs, 0, cfg)
    sb3.reset()
    core = EnvCore(cfg, envs)
    for e in range(envs):
        core.reset_world(e, np.random.default_rng(e))
    return {
        "VCPPVecEnv": batched_rate(sb3.step, envs, seconds),
        "EnvCore": batched_rate(core.step, envs, seconds),
    }


def old_core_rates(rev: str, settings: dict, envs: int, seconds: float) -> dict[str, float]:
    """:func:`core_rates` of the code at git revision ``rev``, in a child process."""
    import json
    import tempfile

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    folder = tempfile.mkdtemp(prefix="pirl-old-")
    archive = subprocess.run(
        ["git", "archive", rev, "src"], cwd=root, capture_output=True, check=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
    code = (
        "import json, sys; sys.path.insert(0, 'benchmarks');"
        "from env_throughput import core_rates;"
        f"print(json.dumps(core_rates(json.loads(sys.argv[1]), {envs}, {seconds})))"
    )
    env = dict(os.environ, PYTHONPATH=os.path.join(folder, "src"), PYTHONWARNINGS="ignore")
    out = subprocess.run(
        [sys.executable, "-c", code, json.dumps(settings)],
        capture_output=True, text=True, env=env, cwd=root, check=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def compare(rev: str, settings: dict, envs: int, seconds: float) -> None:
    """This code's batched rows against revision ``rev``'s, interleaved, best of two."""
    new: dict[str, float] = {}
    old: dict[str, float] = {}
    for _ in range(2):
        for key, value in old_core_rates(rev, settings, envs, seconds).items():
            old[key] = max(old.get(key, 0.0), value)
        for key, value in core_rates(settings, envs, seconds).items():
            new[key] = max(new.get(key, 0.0), value)
    print(f"\nagainst {rev} ({envs} worlds): agent-steps/s, this code / {rev}")
    for key in new:
        print(f"{key:<28} {new[key]:>12,.0f} {old[key]:>12,.0f} {new[key] / old[key]:>8.2f}x")


def compare_site(site: str, settings: dict, envs: int, seconds: float) -> None:
    """The batched rows on ``site`` against ``settings``' size, interleaved, best of two."""
    from pirl.world.memory import world_bytes
    from pirl.world.seeable import with_site

    on_site = {**settings, "site": site}
    site_cfg = with_site(VCPPConfig(**{**settings, "size": tuple(settings["size"])}), site)
    ours, theirs = {}, {}
    for _ in range(2):
        for into, what in ((ours, on_site), (theirs, settings)):
            for key, value in core_rates(what, envs, seconds).items():
                into[key] = max(into.get(key, 0.0), value)
    size = "x".join(str(v) for v in settings["size"])
    grid = "x".join(str(v) for v in site_cfg.size)
    base_cfg = VCPPConfig(**{**settings, "size": tuple(settings["size"])})
    print(f"\nsite {site} ({grid}) against {size} ({envs} worlds): world-steps/s")
    for key in ours:
        print(f"{key:<28} {ours[key]:>12,.0f} vs {theirs[key]:>12,.0f}  "
              f"{ours[key] / theirs[key]:.2f}x")  # fmt: skip
    print(f"memory per world: {world_bytes(site_cfg) / 2**20:.1f} MiB on the site, "
          f"{world_bytes(base_cfg) / 2**20:.2f} MiB at {size}")  # fmt: skip


def fleet_rates(cfg: VCPPConfig, uavs: int, envs: int, seconds: float) -> dict[str, float]:
    """UAV-steps/s of the fleet VecEnv and of the core with ``uavs`` UAVs per world, about
    ``envs`` UAVs in all."""
    from pirl.env.fleet import make_fleet_vec_env

    fleet = cfg.replace(uavs=uavs)
    worlds = max(1, envs // uavs)
    slots = worlds * uavs
    vec = make_fleet_vec_env(worlds, 0, fleet)
    vec.reset()
    core = EnvCore(fleet, worlds)
    for e in range(worlds):
        core.reset_world(e, np.random.default_rng(e))

    def vec_step(actions: np.ndarray) -> None:
        vec.step_async(actions)
        vec.step_wait()

    return {
        "FleetVecEnv (SB3)": batched_rate(vec_step, slots, seconds),
        "EnvCore": batched_rate(core.step, slots, seconds),
    }


def compare_fleets(cfgs: dict[str, VCPPConfig], uavs: list[int], envs: int, seconds: float) -> None:
    """UAV-steps/s at each K on each world, interleaved, best of two; ratios to K = 1."""
    best: dict[tuple[str, int], dict[str, float]] = {}
    for _ in range(2):
        for name, cfg in cfgs.items():
            for k in uavs:
                for key, value in fleet_rates(cfg, k, envs, seconds).items():
                    row = best.setdefault((name, k), {})
                    row[key] = max(row.get(key, 0.0), value)
    print(f"\nfleets (about {envs} UAVs in all): UAV-steps/s, and as a ratio of K = 1")
    for name in cfgs:
        for k in uavs:
            cells = []
            for key, value in best[(name, k)].items():
                one = best.get((name, 1), {}).get(key)
                ratio = f" ({value / one:.2f}x)" if one else ""
                cells.append(f"{key} {value:>10,.0f}{ratio}")
            print(f"{name:<14} K={k:<3} " + "   ".join(cells))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="timing per row")
    parser.add_argument("--envs", type=int, default=64, help="worlds in the batched envs")
    parser.add_argument("--size", default="60x60x3")
    parser.add_argument("--footprint", default="paper", choices=("paper", "frustum"))
    parser.add_argument("--threads", action="store_true", help="also numba threads (parallel)")
    parser.add_argument("--against", metavar="REV", help="also measure git revision REV")
    parser.add_argument("--settings", default="{}", help="JSON of extra env settings")
    parser.add_argument("--site", help="also measure on this site folder, against --size")
    parser.add_argument("--uavs", help="fleet sizes to measure, e.g. 1,4,8 (alone: only them)")
    parser.add_argument("--baseline-settings", metavar="JSON",
                        help="also measure the batched rows with these extra env settings "
                             "instead, and print --settings' rate as a ratio of them")  # fmt: skip
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    import json

    extra = json.loads(args.settings)
    settings = {"size": list(size), "footprint": args.footprint, **extra}
    cfg = VCPPConfig(size=size, footprint=args.footprint, **extra)
    n = args.envs
    if args.uavs:
        cfgs = {args.size: cfg}
        if args.site:
            from pirl.world.seeable import with_site

            cfgs[os.path.basename(args.site.rstrip("/"))] = with_site(cfg, args.site)
        ks = sorted({1, *(int(v) for v in args.uavs.split(","))})
        compare_fleets(cfgs, ks, n, args.seconds)
        return

    rows: list[tuple[str, float]] = [("naive (numba off)", naive_rate(settings, args.seconds))]
    rows.append(("single VCPPEnv", single_rate(settings, args.seconds)))
    sync = gym.make_vec("pirl/VCPP-v0", num_envs=8, vectorization_mode="sync", **settings)
    sync.reset(seed=0)
    rows.append(("SyncVectorEnv(8)", batched_rate(sync.step, 8, args.seconds)))
    for parallel in (False, True) if args.threads else (False,):
        tag = ", threads" if parallel else ""
        vector = VCPPVectorEnv(n, cfg, parallel=parallel)
        vector.reset(seed=0)
        rows.append((f"VCPPVectorEnv({n}{tag})", batched_rate(vector.step, n, args.seconds)))
        sb3 = make_vec_env(n, 0, cfg, parallel=parallel)
        sb3.reset()
        rows.append((f"VCPPVecEnv({n}{tag}, SB3)", batched_rate(sb3.step, n, args.seconds)))
        core = EnvCore(cfg, n, parallel)
        for e in range(n):
            core.reset_world(e, np.random.default_rng(e))
        rows.append((f"EnvCore({n}{tag})", batched_rate(core.step, n, args.seconds)))

    naive, single = rows[0][1], rows[1][1]
    print(f"{args.size} {args.footprint}, random actions, agent-steps/s (best third of "
          f"{args.seconds:g} s per row)")  # fmt: skip
    print(f"{'env':<28} {'steps/s':>12} {'x naive':>8} {'x single':>9}")
    for name, value in rows:
        print(f"{name:<28} {value:>12,.0f} {value / naive:>8.1f} {value / single:>9.1f}")
    if args.against:
        compare(args.against, settings, n, args.seconds)
    if args.site:
        compare_site(args.site, settings, n, args.seconds)
    if args.baseline_settings:
        base = {"size": list(size), "footprint": args.footprint}
        base.update(json.loads(args.baseline_settings))
        # Interleaved, best of two each, so drift on a shared machine hits both alike.
        ours, theirs = {}, {}
        for _ in range(2):
            for into, what in ((ours, settings), (theirs, base)):
                for key, value in core_rates(what, n, args.seconds).items():
                    into[key] = max(into.get(key, 0.0), value)
        print(f"--settings {args.settings} against --baseline-settings {args.baseline_settings}:")
        for key in ours:
            print(
                f"{key + f'({n})':<28} {ours[key]:>12,.0f} vs {theirs[key]:>12,.0f}  "
                f"{ours[key] / theirs[key]:.2f}x"
            )


if __name__ == "__main__":
    main()
