"""Adversarial calibration trust benchmark: how often does each method return a WRONG answer?

Run from the repository root after installing the wheel:
    python benches/adversarial.py [--scenes N] [--workers 2] [--families corner poles ...]
        [--methods auto targetless ...] [--json OUT] [--start-seed S] [--save-wrong DIR]
        [--condition narrow-fov]

Scenes come from :mod:`lidarcal.scenarios`, spread evenly over the families (scene ``i`` of a
family is ``scenarios.make(family, start_seed + i)``), under ``--condition`` if given
(``scenarios.degrade``: a narrow field of view, a sparse target, spurious returns). Every
method the scene lists is called through ``lidarcal.calibrate`` and each outcome is classed as

* solved -- returned, rotation error <= 0.05 rad and translation error <= 0.10 m;
* wrong -- returned with a larger error: the number to drive to zero;
* refused right -- ``CalibrationError`` on a scene that is not (or not surely) solvable;
* refused solvable -- ``CalibrationError`` on a scene that is solvable;
* error -- ``ValueError`` (a refusal, but counted apart) or any other exception (a bug: listed).

Errors: rotation = angle of ``R_true^T R_est``; translation = norm of the translation of
``inv(T_true) @ T_est``.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import sys
import time
import traceback
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

if TYPE_CHECKING:
    from lidarcal.calibrate import Method

ROT_TOL = 0.05  # rad
TRANS_TOL = 0.10  # m
ALL_METHODS = ("auto", "planes", "targetless", "poles")
OUTCOMES = ("solved", "wrong", "refused_right", "refused_solvable", "error")


def pose_errors(truth: np.ndarray, est: np.ndarray) -> tuple[float, float]:
    """(rotation angle of R_true^T R_est in rad, |translation of inv(T_true) T_est| in m)."""
    r = truth[:3, :3].T @ est[:3, :3]
    rot = math.acos(max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0)))
    delta = np.linalg.inv(truth) @ est
    return rot, float(np.linalg.norm(delta[:3, 3]))


def _plain(value: Any) -> Any:
    """A JSON-friendly copy of a result attribute (None when not cheap to show)."""
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, (tuple, list)) and len(value) <= 6:
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray) and value.size <= 6:
        return [_plain(v) for v in value.ravel().tolist()]
    return None


def result_attributes(result: Any) -> dict[str, Any]:
    """Cheap attributes of a result worth printing next to a wrong case."""
    details, refinement = result.details, result.refinement
    values: dict[str, Any] = {
        "method": result.method,
        "converged": refinement.converged,
        "termination": refinement.termination,
    }
    if result.method == "planes":
        values.update(
            ordering_margin=details.ordering["margin"], used_up=details.ordering["used_up"]
        )
    elif result.method == "poles":
        values.update(ambiguous=details.ambiguous, hypothesis_margin=details.margin)
    else:
        values.update(
            ambiguous=details.ambiguous,
            matched_planes=len(details.planes_reference),
            agreement=details.agreement,
            best_score=details.best_score,
            second_score=details.second_score,
            sweep=details.sweep,
            triplet=details.triplet,
            icp_fitness=None if details.icp is None else details.icp["fitness"],
            weakest_translation_share=float(details.weakest_translation[1]),
        )
    check = getattr(result, "check", None)
    if check is not None:
        values.update(
            check_overlap=check.overlap,
            check_agreement=[check.agreement, check.reverse_agreement],
            check_violations=[check.violations, check.reverse_violations],
            check_correction=[check.correction_rotation_deg, check.correction_translation_m],
            check_gain=check.agreement_gain,
            check_weakest_share=check.weakest_translation_share,
        )
    plain = {name: _plain(value) for name, value in values.items()}
    return {name: value for name, value in plain.items() if value is not None}


Task = tuple[str, int, tuple[str, ...] | None, str]


def run_scene(task: Task) -> tuple[str, int, list[dict[str, Any]]]:
    """Generates one scene and runs each of its methods (those in the filter, if any)."""
    import lidarcal
    from lidarcal import scenarios

    family, seed, method_filter, condition = task
    t0 = time.perf_counter()
    try:
        scene = scenarios.degrade(scenarios.make(family, seed), condition)
    except Exception as e:  # a generator failure is a bench bug: report it, keep going
        failure = {
            "family": family,
            "seed": seed,
            "method": "(generator)",
            "condition": condition,
            "outcome": "error",
            "exception": type(e).__name__,
            "message": str(e),
            "traceback": traceback.format_exc(),
            "time_s": time.perf_counter() - t0,
        }
        return family, seed, [failure]
    generate_s = time.perf_counter() - t0
    truth = scene.reference_from_target
    records = []
    for method in scene.methods:
        if method_filter is not None and method not in method_filter:
            continue
        rec: dict[str, Any] = {
            "family": family,
            "seed": seed,
            "method": method,
            "condition": condition,
            "solvable": scene.solvable,
            "generate_s": generate_s,
            "points": [int(scene.reference.shape[0]), int(scene.target.shape[0])],
        }
        t1 = time.perf_counter()
        try:
            result = lidarcal.calibrate(
                scene.reference, scene.target, method=cast("Method", method)
            )
        except lidarcal.CalibrationError as e:
            rec["time_s"] = time.perf_counter() - t1
            rec["outcome"] = "refused_solvable" if scene.solvable else "refused_right"
            rec["kind"] = _plain(getattr(e, "kind", None))
            rec["message"] = str(e)
        except ValueError as e:
            rec["time_s"] = time.perf_counter() - t1
            rec["outcome"] = "error"
            rec["exception"] = type(e).__name__
            rec["message"] = str(e)
        except Exception as e:  # anything else is a bug in the library
            rec["time_s"] = time.perf_counter() - t1
            rec["outcome"] = "error"
            rec["exception"] = type(e).__name__
            rec["message"] = str(e)
            rec["traceback"] = traceback.format_exc()
        else:
            rec["time_s"] = time.perf_counter() - t1
            rot, trans = pose_errors(truth, np.asarray(result.transform, dtype=np.float64))
            rec["rot_rad"] = rot
            rec["trans_m"] = trans
            wrong = not (rot <= ROT_TOL and trans <= TRANS_TOL)  # NaN counts as wrong
            rec["outcome"] = "wrong" if wrong else "solved"
            rec["result"] = result_attributes(result)
            rec["estimate"] = np.asarray(result.transform, dtype=np.float64).tolist()
        if rec["outcome"] == "wrong":
            rec["description"] = scene.description
        records.append(rec)
    return family, seed, records


def tasks(
    families: Sequence[str],
    scenes: int,
    start_seed: int,
    methods: tuple[str, ...] | None,
    condition: str = "none",
) -> list[Task]:
    """``scenes`` scenes spread evenly over ``families`` (the first ones get the remainder),
    interleaved so that progress covers every family."""
    per = [
        scenes // len(families) + (1 if i < scenes % len(families) else 0)
        for i in range(len(families))
    ]
    out = []
    for i in range(max(per, default=0)):
        for family, n in zip(families, per, strict=True):
            if i < n:
                out.append((family, start_seed + i, methods, condition))
    return out


def _row(label: str, counts: dict[str, int], scenes: int | str) -> str:
    return (
        f"| {label} | {scenes} | {counts['solved']} | {counts['wrong']} | "
        f"{counts['refused_right']} | {counts['refused_solvable']} | {counts['error']} |"
    )


def report(
    records: list[dict[str, Any]], families: Sequence[str], wall_s: float, condition: str = "none"
) -> None:
    if condition != "none":
        print(f"Condition: {condition} (scenarios.degrade)")
        print()
    methods = [m for m in ALL_METHODS if any(r["method"] == m for r in records)]
    by: dict[tuple[str, str], dict[str, int]] = defaultdict(lambda: dict.fromkeys(OUTCOMES, 0))
    scene_count: dict[tuple[str, str], set[tuple[str, int]]] = defaultdict(set)
    for r in records:
        for key in ((r["family"], r["method"]), ("*", r["method"]), ("*", "*")):
            by[key][r["outcome"]] += 1
            scene_count[key].add((r["family"], r["seed"]))
    print(
        "| family | method | scenes | solved | wrong | refused right | refused solvable | errors |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for family in families:
        for method in methods:
            key = (family, method)
            if key in by:
                print(_row(f"{family} | {method}", by[key], len(scene_count[key])))
    for method in methods:
        key = ("*", method)
        if key in by:
            print(_row(f"**all** | {method}", by[key], len(scene_count[key])))
    if ("*", "*") in by:
        print(_row("**all** | **all**", by[("*", "*")], f"{len(scene_count[('*', '*')])} scenes"))

    returned = sum(1 for r in records if r["outcome"] in ("solved", "wrong"))
    wrong = [r for r in records if r["outcome"] == "wrong"]
    print()
    print(
        f"{len(records)} calibrations, {returned} returned, {len(wrong)} wrong"
        + (f" ({len(wrong) / returned:.1%} of returned)" if returned else "")
    )
    times = [r["time_s"] for r in records if "time_s" in r]
    if times:
        per_method = defaultdict(list)
        for r in records:
            if "time_s" in r:
                per_method[r["method"]].append(r["time_s"])
        parts = ", ".join(
            f"{m} {np.mean(v):.2f} s mean / {np.max(v):.1f} s max" for m, v in per_method.items()
        )
        print(f"Time per calibration: {parts}")

    if wrong:
        print()
        print(
            'WRONG answers (reproduce: python -c "from lidarcal import scenarios; '
            f"s = scenarios.degrade(scenarios.make('FAMILY', SEED), '{condition}')\"):"
        )
        print(
            "| family | seed | method | returned by | rot (deg) | trans (cm) | solvable | result |"
        )
        print("|---|---|---|---|---|---|---|---|")
        for r in sorted(wrong, key=lambda r: (r["family"], r["seed"], r["method"])):
            res = dict(r.get("result", {}))
            by_method = res.pop("method", "?")
            extra = ", ".join(f"{k}={_short(v)}" for k, v in res.items())
            print(
                f"| {r['family']} | {r['seed']} | {r['method']} | {by_method} | "
                f"{math.degrees(r['rot_rad']):.2f} | {100 * r['trans_m']:.1f} | "
                f"{r['solvable']} | {extra} |"
            )
    errors = [r for r in records if r["outcome"] == "error"]
    if errors:
        print()
        print("ERRORS (ValueError counts as a refusal; anything else is a bug):")
        for r in errors:
            print(
                f"- {r['family']} {r['seed']} {r['method']}: {r.get('exception')}: "
                f"{r.get('message', '')[:300]}"
            )
            if "traceback" in r:
                print("  " + r["traceback"].strip().replace("\n", "\n  "))
    print()
    print(f"Total wall time: {wall_s:.1f} s")


def _short(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    if isinstance(v, list):
        return "[" + ", ".join(_short(x) for x in v) + "]"
    return str(v)


def save_wrong(records: Iterable[dict[str, Any]], directory: Path) -> None:
    from lidarcal import scenarios

    directory.mkdir(parents=True, exist_ok=True)
    done = set()
    for r in records:
        if r["outcome"] != "wrong" or (r["family"], r["seed"]) in done:
            continue
        done.add((r["family"], r["seed"]))
        s = scenarios.degrade(scenarios.make(r["family"], r["seed"]), r.get("condition", "none"))
        methods = sorted(
            x["method"]
            for x in records
            if x["outcome"] == "wrong" and (x["family"], x["seed"]) == (r["family"], r["seed"])
        )
        np.savez_compressed(
            directory / f"{r['family']}_{r['seed']}.npz",
            reference=s.reference,
            target=s.target,
            reference_from_target=s.reference_from_target,
            wrong_methods=np.array(methods),
            description=np.array(s.description),
        )


def main(argv: Sequence[str] | None = None) -> int:
    from lidarcal import scenarios

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=1000, help="total scenes (default 1000)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument(
        "--families", nargs="+", default=list(scenarios.FAMILIES), choices=scenarios.FAMILIES
    )
    parser.add_argument(
        "--methods",
        nargs="+",
        default=None,
        choices=ALL_METHODS,
        help="only these methods (default: each scene's own list)",
    )
    parser.add_argument("--json", type=Path, default=None, help="write every record here")
    parser.add_argument("--start-seed", type=int, default=0)
    parser.add_argument(
        "--save-wrong",
        type=Path,
        default=None,
        metavar="DIR",
        help="write each scene with a wrong answer as DIR/<family>_<seed>.npz",
    )
    parser.add_argument(
        "--condition",
        default="none",
        choices=scenarios.CONDITIONS,
        help="put every scene under this condition (scenarios.degrade; default none)",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=600.0,
        help="give up when no scene finishes for this many seconds (a hang)",
    )
    args = parser.parse_args(argv)

    methods = tuple(args.methods) if args.methods else None
    work = tasks(args.families, args.scenes, args.start_seed, methods, args.condition)
    records: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    done = 0
    pending = {(f, s) for f, s, _, _ in work}
    hung = False

    def progress() -> None:
        wrong = sum(r["outcome"] == "wrong" for r in records)
        print(
            f"[{done}/{len(work)} scenes, {time.perf_counter() - t0:.0f} s, {wrong} wrong]",
            file=sys.stderr,
            flush=True,
        )

    if args.workers <= 1:
        for task in work:
            family, seed, recs = run_scene(task)
            records.extend(recs)
            done += 1
            pending.discard((family, seed))
            if done % 50 == 0:
                progress()
    else:
        ctx = mp.get_context("spawn")
        with ctx.Pool(args.workers, maxtasksperchild=200) as pool:
            it = pool.imap_unordered(run_scene, work, chunksize=1)
            while True:
                try:
                    family, seed, recs = it.next(timeout=args.timeout)
                except StopIteration:
                    break
                except mp.TimeoutError:
                    hung = True
                    print(
                        f"HANG: no scene finished in {args.timeout:.0f} s; still pending "
                        f"(the first ones are running): {sorted(pending)[:10]}",
                        file=sys.stderr,
                    )
                    pool.terminate()
                    break
                pending.discard((family, seed))
                records.extend(recs)
                done += 1
                if done % 50 == 0:
                    progress()
    wall_s = time.perf_counter() - t0
    records.sort(key=lambda r: (r["family"], r["seed"], r["method"]))
    report(records, args.families, wall_s, args.condition)
    if hung:
        print(f"HANG: gave up with {len(pending)} scenes pending: {sorted(pending)[:20]}")
    if args.json is not None:
        args.json.write_text(json.dumps(records, indent=1))
    if args.save_wrong is not None:
        save_wrong(records, args.save_wrong)
    return 0


if __name__ == "__main__":
    sys.exit(main())
