#!/usr/bin/env python3
"""Bring your own estimator: a stand-alone example for `vmt study --estimator-cmd` and `vmt score`.

    python3 examples/my_estimator.py DATA_DIR ESTIMATE.csv

Reads a vmt measurement set (docs/formats.md §1) and writes the six error motions of the axis as a profile
CSV (docs/formats.md §5): `position`, then `positioning`, `straightness_y`, `straightness_z`, `roll`,
`pitch`, `yaw` (m and rad). Python standard library only.

Method: the laser lines of a point-table run (the nine-line measurement, docs/methods.md "laser line-set
identification"), solved target by target. A laser with sensitive direction d (machine frame) whose
measuring point sits at r (m, axis frame) on the moving body reads, to first order,

    reading = d · (E + ε × r) = d · E + ε · (r × d)

with E = (EXX, EYX, EZX) the translational and ε = (EAX, EBX, ECX) = (roll, pitch, yaw) the angular error
motions at that position. Each reading is one linear equation in the six unknowns; at every target the
mean reading of each laser (over runs and directions) gives one equation per laser, solved by least
squares. Six lasers at well-spread points (three along X at different heights and sides, two across in Y
at different heights, one across in Z) determine all six motions. No line or offset is removed here:
`vmt score` compares straightness about its least-squares line and the rest relative to the first position.
"""

import csv
import os
import sys
import tomllib

LINE_KINDS = ("laser_linear", "laser_straightness")


def fail(message):
    print(f"my_estimator: {message}", file=sys.stderr)
    sys.exit(2)


def unit_factor(cell):
    """(name, factor to SI) of a header cell `name[unit]`; only the units vmt writes for lasers."""
    factors = {None: 1.0, "m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "nm": 1e-9, "rad": 1.0, "urad": 1e-6}
    name, _, unit = cell.strip().partition("[")
    unit = unit.rstrip("]") or None
    if unit not in factors:
        fail(f"unit [{unit}] of column {name} not handled by this example")
    return name, factors[unit]


def solve_least_squares(rows, rhs):
    """x minimising |A x − b| through the normal equations (A has full column rank here)."""
    n = len(rows[0])
    m = [[sum(r[i] * r[j] for r in rows) for j in range(n)] + [sum(r[i] * b for r, b in zip(rows, rhs))]
         for i in range(n)]
    for c in range(n):  # Gauss–Jordan with partial pivoting
        p = max(range(c, n), key=lambda k: abs(m[k][c]))
        if abs(m[p][c]) < 1e-300:
            fail("the laser lines do not determine all six error motions (singular system)")
        m[c], m[p] = m[p], m[c]
        for k in range(n):
            if k != c:
                f = m[k][c] / m[c][c]
                m[k] = [a - f * b for a, b in zip(m[k], m[c])]
    return [m[i][n] / m[i][i] for i in range(n)]


def main():
    if len(sys.argv) != 3:
        fail("usage: my_estimator.py DATA_DIR ESTIMATE.csv")
    data, out = sys.argv[1], sys.argv[2]
    with open(os.path.join(data, "manifest.toml"), "rb") as f:
        manifest = tomllib.load(f)
    lasers = {s["name"]: s for s in manifest.get("sensors", []) if s.get("kind") in LINE_KINDS}
    for run in manifest.get("runs", []):
        with open(os.path.join(data, run["file"]), newline="") as f:
            rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
        header = [unit_factor(c) for c in rows[0]]
        names = [h[0] for h in header]
        used = [n for n in names if n in lasers]
        if "target" in names and len(used) >= 6:
            break
    else:
        fail("no point-table run with at least six laser lines (run the nine-line procedure)")
    col = {n: i for i, n in enumerate(names)}
    sums = {}  # target -> laser -> [sum, count]
    for r in rows[1:]:
        x = float(r[col["target"]]) * header[col["target"]][1]
        for n in used:
            acc = sums.setdefault(x, {}).setdefault(n, [0.0, 0])
            acc[0] += float(r[col[n]]) * header[col[n]][1]
            acc[1] += 1
    # One equation row per laser: [d, r × d] · [E, ε].
    coefficients = {}
    for n in used:
        s = lasers[n]
        if "position" not in s:
            fail(f"sensor {n} has no measuring-point position in the manifest")
        d, p = s["direction"], s["position"]
        cross = [p[1] * d[2] - p[2] * d[1], p[2] * d[0] - p[0] * d[2], p[0] * d[1] - p[1] * d[0]]
        coefficients[n] = list(d) + cross
    with open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["position", "positioning", "straightness_y", "straightness_z", "roll", "pitch", "yaw"])
        for x in sorted(sums):
            means = sums[x]
            a = [coefficients[n] for n in used]
            b = [means[n][0] / means[n][1] for n in used]
            w.writerow([repr(x)] + [repr(v) for v in solve_least_squares(a, b)])


if __name__ == "__main__":
    main()
