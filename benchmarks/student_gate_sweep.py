"""How much of its teacher's signal a student learns, by teacher: the figures the student's
gate is chosen on (pare.student_gate_on, pare.student_kappa_gate; docs/advice.md).

For each teacher (the oracle at several accuracies, and optionally the embedded LLM) it asks
the teacher about distillation states (planner and random rollouts on scenario seeds from
2,000,000 on: neither training's nor evaluation's), fits a student as ``pirl distill`` does,
and prints its held-out agreement, the majority baseline, Cohen's kappa over the fields the
teacher varies, and which fields those are.

    .venv/bin/python benchmarks/student_gate_sweep.py --states 1500 [--llm 400]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=1500, help="teacher answers per oracle")
    parser.add_argument("--accuracies", default="1.0,0.75,0.5,0.25,0.0")
    parser.add_argument("--llm", type=int, default=0, help="answers of the embedded LLM (0: skip)")
    parser.add_argument("--config", default="quick")
    parser.add_argument("--fit-steps", type=int, default=2000)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    os.environ.setdefault("PIRL_CACHE_DIR", tempfile.mkdtemp(prefix="pirl-gate-"))

    from pirl.agents.distill import distill
    from pirl.config.presets import preset_path as _preset
    from pirl.config.run import RunConfig

    base = RunConfig.from_yaml(_preset(args.config, "--config"))
    teachers = [("oracle", float(a), args.states) for a in args.accuracies.split(",")]
    if args.llm:
        teachers.append(("local", 1.0, args.llm))
    rows = []
    root = Path(tempfile.mkdtemp(prefix="pirl-gate-students-"))
    for name, accuracy, states in teachers:
        cfg = base.with_overrides(advisor={"oracle_accuracy": accuracy})
        out = root / f"{name}-{accuracy:g}"
        record = distill(
            cfg, name, states, out, seed=0, fit_steps=args.fit_steps, progress=None,
            log=lambda _m: None,
        )  # fmt: skip
        from pirl.advice.student import Student

        student = Student.load(out / "student.npz", None)
        score = student.score
        rows.append(
            {
                "teacher": record["teacher_label"],
                "answers": record["answers_ok"],
                "agreement": round(score.agreement, 3),
                "majority": round(score.majority, 3),
                "kappa": round(score.kappa, 3),
                "informative": list(score.informative),
                "per_field_kappa": {k: round(v, 3) for k, v in score.per_field_kappa.items()},
            }
        )
        r = rows[-1]
        print(
            f"{r['teacher']:<40} answers {r['answers']:>5}  agreement {r['agreement']:.3f}  "
            f"majority {r['majority']:.3f}  kappa {r['kappa']:.3f}  "
            f"varies: {', '.join(r['informative']) or 'none'}",
            flush=True,
        )
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
