#!/usr/bin/env python3
"""Times `stiffsim run` over an ensemble of perturbed starts, optionally against
a second binary, for scenes whose runs are chaotic.

    python3 bench/ensemble.py [--runs N] [--accuracy A] [--vs BINARY_B]
                              [--json FILE] BINARY_A SCENE [run options...]

A folding sheet at a large fixed step is chaotic: a change at the level of
round-off (a different summation order, a Newton iteration that stops one
update earlier) takes the run through another sequence of folds, with other
Newton counts and other halvings. On models/cloth.yaml at 1/60 over 2 s the
same binary at accuracy 1e-3 (1 + 1e-7) against 1e-3 gave median times 0.93
and 1.04 of each other, so one run per binary, or many runs of one start,
measures which path the run took rather than what the code costs.

Each start k = 0 .. N-1 runs at accuracy A (1 + k 1e-7): the same scene, the
same Newton tolerance to seven digits, a different path through the folds.
With --vs, binary A and binary B run each start in turn (A B A B ...), so
that a drift of the machine's speed reaches both, and the ratio of their
times is taken per start; its median is the comparison to quote. The wall
time is the whole process's. The statistics are read from each run's
--stats file: step halvings (substep_failures), factorizations and Newton
iterations.

Prints one line per binary (median, min and max time; runs with a halving
and halvings in all; median factorizations and Newton iterations) and, with
--vs, the paired ratio. --json writes every run's figures too. Exits non-zero
if a run fails.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

PERTURBATION = 1e-7


def run_once(binary, scene, options, accuracy, stats_path):
    command = [binary, "run", scene, *options, "-q", "--accuracy", repr(accuracy),
               "--stats", stats_path]
    began = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - began
    if result.returncode != 0:
        sys.exit("ensemble: %s exited with %d: %s" % (" ".join(command), result.returncode,
                                                      result.stderr.strip()))
    with open(stats_path) as f:
        stats = json.load(f)["statistics"]
    return {
        "accuracy": accuracy,
        "seconds": seconds,
        "halvings": stats["substep_failures"],
        "factorizations": stats["iteration_matrix_factorizations"],
        "newton_iterations": stats["newton_raphson_iterations"],
    }


def summary(runs):
    times = [r["seconds"] for r in runs]
    return {
        "median_seconds": statistics.median(times),
        "min_seconds": min(times),
        "max_seconds": max(times),
        "runs_with_halvings": sum(r["halvings"] > 0 for r in runs),
        "halvings": sum(r["halvings"] for r in runs),
        "median_factorizations": statistics.median(r["factorizations"] for r in runs),
        "median_newton_iterations": statistics.median(r["newton_iterations"] for r in runs),
    }


def describe(name, s, count):
    return ("%s: median %.3f s (%.3f-%.3f), halvings in %d of %d runs (%d in all), "
            "median %g factorizations, %g Newton iterations" %
            (name, s["median_seconds"], s["min_seconds"], s["max_seconds"],
             s["runs_with_halvings"], count, s["halvings"], s["median_factorizations"],
             s["median_newton_iterations"]))


def main():
    parser = argparse.ArgumentParser(
        description="Times stiffsim run over perturbed starts (see the module docstring).")
    parser.add_argument("--runs", type=int, default=8, help="starts in the ensemble (default 8)")
    parser.add_argument("--accuracy", type=float, default=1e-3,
                        help="the accuracy the starts perturb (default 1e-3)")
    parser.add_argument("--vs", metavar="BINARY_B", help="a second binary, run in alternation")
    parser.add_argument("--json", metavar="FILE", help="write every run's figures here")
    parser.add_argument("binary", help="the stiffsim binary (A)")
    parser.add_argument("scene")
    parser.add_argument("options", nargs=argparse.REMAINDER,
                        help="options for `stiffsim run` (not --accuracy, --stats or -q)")
    args = parser.parse_args()
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    for reserved in ("--accuracy", "--stats"):
        if any(o == reserved or o.startswith(reserved + "=") for o in args.options):
            parser.error("%s is set by the ensemble; leave it out of the run options" % reserved)
    if not 0.0 < args.accuracy * (1.0 + PERTURBATION * (args.runs - 1)) <= 1.0:
        parser.error("--accuracy must stay in (0, 1] for every start")

    binaries = {"A": args.binary}
    if args.vs:
        binaries["B"] = args.vs
    runs = {name: [] for name in binaries}
    with tempfile.TemporaryDirectory() as directory:
        stats_path = os.path.join(directory, "stats.json")
        for k in range(args.runs):
            accuracy = args.accuracy * (1.0 + PERTURBATION * k)
            for name, binary in binaries.items():
                runs[name].append(run_once(binary, args.scene, args.options, accuracy, stats_path))

    report = {"scene": args.scene, "options": args.options, "runs": args.runs, "binaries": {}}
    for name, binary in binaries.items():
        s = summary(runs[name])
        report["binaries"][name] = {"binary": binary, "summary": s, "runs": runs[name]}
        print(describe("%s (%s)" % (name, binary), s, args.runs))
    if args.vs:
        ratios = [a["seconds"] / b["seconds"] for a, b in zip(runs["A"], runs["B"])]
        report["paired_ratio"] = {"median": statistics.median(ratios), "min": min(ratios),
                                  "max": max(ratios)}
        print("paired ratio A/B: median %.3f (%.2f-%.2f)" % (statistics.median(ratios), min(ratios),
                                                             max(ratios)))
    if args.json:
        # Written whole or not at all.
        partial = args.json + ".partial"
        with open(partial, "w") as f:
            json.dump(report, f, indent=1)
        os.replace(partial, args.json)


if __name__ == "__main__":
    main()
