#!/usr/bin/env python3
"""The rapier reference step (or with --engine fast the fast step) of several versions of vmt-sim, measured in one run (issue 15: "the rapier
reference step >= 1.2x faster than today", today being main when the issue was filed).

    python3 benches/anchors/reference_step_ab.py [--rounds 15] [--steps 20000] [--cases 0,1,2] \
        [--keep DIR] LABEL=TREE [LABEL=TREE ...]

For each TREE (a git worktree of vmt at some commit) it writes sim/examples/reference_step_server.rs
(two include! lines: reference_step/api_*.rs, the cases in that tree's API, chosen by whether the
tree's vmt-sim has `enum Fidelity`, and reference_step/common.rs, the stepping loop), builds it with
`nice cargo build --release -p vmt-sim --example reference_step_server`, copies the binary aside and
removes the file again. Each tree builds in its own target
directory (seed it with `cp -a` of a built one): one shared directory maps the same package at two
paths to one artifact (cargo's dep-info paths are relative to the workspace), so one tree's build would
silently run another tree's code. Each case then starts one server per tree (same scenario, same start, same
command, same step count) and alternates rounds of --steps steps between them, the order reversed
every other round (A B, B A, ...), after one untimed warm-up round each. It prints each version's
median and min of the per-round us/step, and the per-round ratios (each version over the last one
named) as median [min, max] over the rounds: the load of a shared machine hits both sides alike.
"""
import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
EXAMPLE = "reference_step_server"


def build(label, tree, out_dir):
    """Builds the step server against TREE's vmt-sim; returns the path of the binary."""
    machine = open(os.path.join(tree, "sim/src/machine.rs")).read()
    api = "api_now.rs" if "pub enum Fidelity" in machine else "api_59b65eb.rs"
    examples = os.path.join(tree, "sim/examples")
    created = not os.path.isdir(examples)
    os.makedirs(examples, exist_ok=True)
    src = os.path.join(examples, EXAMPLE + ".rs")
    with open(src, "w") as f:
        f.write(f'include!("{HERE}/reference_step/{api}");\ninclude!("{HERE}/reference_step/common.rs");\n')
    env = dict(os.environ)
    env.pop("CARGO_TARGET_DIR", None)
    try:
        subprocess.run(["nice", "cargo", "build", "--release", "-q", "-p", "vmt-sim", "--example", EXAMPLE],
                       cwd=tree, env=env, check=True)
    finally:
        os.remove(src)
        if created:
            os.rmdir(examples)
    built = os.path.join(tree, "target/release/examples", EXAMPLE)
    dest = os.path.join(out_dir, label)
    shutil.copy2(built, dest)
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=tree, capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=tree,
                           capture_output=True, text=True).stdout.strip()
    print(f"{label}: {tree} at {rev}{' (with uncommitted changes)' if dirty else ''}, cases in {api}", flush=True)
    return dest


def round_trip(proc, steps):
    proc.stdin.write(f"{steps}\n")
    proc.stdin.flush()
    line = proc.stdout.readline()
    if not line:
        sys.exit(f"a step server ended early: {proc.args}")
    return int(line) / steps / 1000.0  # ns per round -> us per step


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--cases", default="0,1,2")
    ap.add_argument("--engine", default="reference", choices=["reference", "fast"],
                    help="the engine stepped (fast: trees from ce7e26e on)")
    ap.add_argument("--keep", default=None, metavar="DIR",
                    help="keep the built servers in DIR (one per LABEL; e.g. for callgrind: printf '10000\\n0\\n' | valgrind --tool=callgrind DIR/LABEL 0)")
    ap.add_argument("--build-only", action="store_true", help="build (into --keep) and stop")
    ap.add_argument("versions", nargs="+", metavar="LABEL=TREE")
    a = ap.parse_args()
    try:
        versions = [v.split("=", 1) for v in a.versions]
        cases = [int(c) for c in a.cases.split(",")]
        assert all(len(v) == 2 for v in versions) and a.rounds > 0 and a.steps > 0
    except (ValueError, AssertionError):
        print("usage: reference_step_ab.py [--rounds N] [--steps N] [--cases 0,1,2] LABEL=TREE ...", file=sys.stderr)
        sys.exit(2)
    out_dir = a.keep or tempfile.mkdtemp(prefix="vmt_reference_step_")
    os.makedirs(out_dir, exist_ok=True)
    bins = [(label, build(label, os.path.abspath(tree), out_dir)) for label, tree in versions]
    if a.build_only:
        return
    print("load before:", open("/proc/loadavg").read().split()[:3], flush=True)
    for case in cases:
        procs = [(label, subprocess.Popen(["nice", b, str(case), a.engine], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True))
                 for label, b in bins]
        for _, p in procs:
            round_trip(p, a.steps)  # warm-up, untimed
        times = {label: [] for label, _ in procs}
        for r in range(a.rounds):
            for label, p in (procs if r % 2 == 0 else procs[::-1]):
                times[label].append(round_trip(p, a.steps))
        finals = []
        for label, p in procs:
            p.stdin.write("0\n")
            p.stdin.flush()
            finals.append((label, p.stdout.readline().strip()))
            p.wait()
        name = finals[0][1].split(":")[0].removeprefix("final ")
        print(f"\ncase {case} ({name}): {a.rounds} rounds of {a.steps} steps each, dt = 1e-4 s, {a.engine} engine")
        last = procs[-1][0]
        for label, _ in procs:
            t = times[label]
            print(f"  {label}: median {statistics.median(t):.3f} us/step, min {min(t):.3f} us/step")
        for label, _ in procs[:-1]:
            ratios = sorted(x / y for x, y in zip(times[label], times[last]))
            q = statistics.quantiles(ratios, n=4) if len(ratios) > 1 else [ratios[0]] * 3
            print(f"  {label}/{last} per round: median {statistics.median(ratios):.3f}, quartiles "
                  f"[{q[0]:.3f}, {q[2]:.3f}], range [{ratios[0]:.3f}, {ratios[-1]:.3f}]; ratio of medians "
                  f"{statistics.median(times[label]) / statistics.median(times[last]):.3f}")
        for label, f in finals:
            print(f"  {label} {f}")
    print("\nload after:", open("/proc/loadavg").read().split()[:3])
    if not a.keep:
        shutil.rmtree(out_dir)


if __name__ == "__main__":
    main()
