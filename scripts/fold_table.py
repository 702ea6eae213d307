#!/usr/bin/env python3
"""Builds a fold table (structure type fold_table, doc/cell_geometry.md) from the FE bag's
loaded h(p) curves, pressure up and back down (`fe_airbag hp --and-back 1`).

Where a curve's bag going up and coming down rest apart at one pressure, the rising state is
the folded branch (middle faces folded in beside the connection) and the falling one the open
branch; where they agree the state is on both. At each pressure the states of one branch, one per load, make a force-height
curve F(h) = load (a heavier load that does not rest lower is left out: F must be one-valued in
h); the table's heights take F and V from it, linearly, and outside it along the end slopes
(stiffened: above the lightest plate the film is stretched, below the heaviest the stack is
squeezed). The snap pressures are the midpoints of the pressure step where the two paths join or
part, per load (a load snaps at most once each way here: the largest pressure wins).

    scripts/fold_table.py --loads 0.6,3,6,10.6,15.6,20.6,30,40 --csv-dir DIR --geometry-tag pillows_n12 \
        --out data/fe/airbag_pillows_n12_fold_table.yaml
"""
import argparse
import csv
import sys

import numpy as np

AGREE_M = 1.5e-3  # rising and falling states closer than this are the same state
TOP_STIFFNESS_N_M = 2000.0  # the plate above the lightest load's rest: the film is stretched
BOTTOM_STIFFNESS_N_M = 1000.0  # below the heaviest load's rest


def read_curve(path):
    rows = []
    with open(path) as f:
        for r in csv.DictReader(f):
            rows.append((float(r["p_gauge_pa"]), float(r["h_m"]), float(r["volume_m3"]), int(r["converged"])))
    top = int(np.argmax([r[0] for r in rows]))
    return rows[: top + 1], rows[top:]  # up, down (both include the top state)


def classify(up, down, load):
    """Per pressure (ascending): the rising state's branch and the falling one's, and the snaps.

    Where the bag going up and the bag coming down rest apart (> AGREE_M) the rising one is
    folded and the falling one open; where they agree the state is on both branches. The fold
    opens where the rising path joins the falling one (between the last pressure apart and the
    next); it closes where the falling path rejoins the rising one. Both per load: the structure
    reads the load as the plate force of the branch the bag would leave."""
    down = {round(r[0]): r for r in down}
    if any(round(u[0]) not in down for u in up):
        return None
    pairs = [(u, down[round(u[0])]) for u in up]
    apart = [abs(u[1] - d[1]) > AGREE_M for u, d in pairs]
    snaps_open, snaps_close = [], []
    for i in range(len(pairs) - 1):
        p_mid = 0.5 * (pairs[i][0][0] + pairs[i + 1][0][0])
        if apart[i] and not apart[i + 1]:
            snaps_open.append((load, p_mid))
        if not apart[i] and apart[i + 1]:
            snaps_close.append((load, p_mid))
    if apart[0]:  # still open at the lowest pressure: it does not fold again there
        snaps_close.append((load, 0.0))
    if apart[-1]:  # still folded at the highest pressure: it does not open there
        snaps_open.append((load, 2.0 * pairs[-1][0][0]))
    return pairs, apart, snaps_open, snaps_close


def column(points, heights):
    """F and V on `heights` from one branch's (h, load, V) states at one pressure."""
    points = sorted(points, key=lambda x: x[1])  # ascending load
    kept = []
    for h, load, v in points:
        if not kept or h < kept[-1][0] - 1e-4:
            kept.append((h, load, v))
    if len(kept) < 2:
        return None
    hs = np.array([k[0] for k in kept])[::-1]
    fs = np.array([k[1] for k in kept])[::-1]
    vs = np.array([k[2] for k in kept])[::-1]
    f = np.interp(heights, hs, fs)
    v = np.interp(heights, hs, vs)
    k_top = max(-(fs[-1] - fs[-2]) / (hs[-1] - hs[-2]), TOP_STIFFNESS_N_M)
    k_bot = max(-(fs[1] - fs[0]) / (hs[1] - hs[0]), BOTTOM_STIFFNESS_N_M)
    a_top = np.clip((vs[-1] - vs[-2]) / (hs[-1] - hs[-2]), 0.0, 0.012)
    a_bot = np.clip((vs[1] - vs[0]) / (hs[1] - hs[0]), 0.002, 0.012)
    above, below = heights > hs[-1], heights < hs[0]
    f[above] = fs[-1] - k_top * (heights[above] - hs[-1])
    v[above] = vs[-1] + a_top * (heights[above] - hs[-1])
    f[below] = fs[0] + k_bot * (hs[0] - heights[below])
    v[below] = np.maximum(vs[0] - a_bot * (hs[0] - heights[below]), 1e-6)
    return f, v


def fill_missing(columns):
    """A pressure where a branch has fewer than two states takes the nearest pressure's column."""
    have = [j for j, c in enumerate(columns) if c is not None]
    if not have:
        sys.exit("a branch has no pressure with two loads")
    return [c if c is not None else columns[min(have, key=lambda i: abs(i - j))] for j, c in enumerate(columns)]


def thresholds(points, default):
    """{load: pressure} from (load, pressure) snaps; the highest pressure where a load has two."""
    out = {}
    for load, p in points:
        out[load] = max(out.get(load, p), p)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--loads", required=True, help="fit loads [N], comma separated")
    ap.add_argument("--csv-dir", required=True)
    ap.add_argument("--geometry-tag", default="pillows_n12")
    ap.add_argument("--heights-mm", default="3,140,56", help="LO,HI,COUNT")
    ap.add_argument("--description", default="")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    loads = [float(x) for x in a.loads.split(",")]
    lo, hi, n = (float(x) for x in a.heights_mm.split(","))
    heights = np.linspace(lo * 1e-3, hi * 1e-3, int(n))
    pressures, by_branch = None, {"folded": {}, "open": {}}
    snaps = {"open": [], "close": []}
    for load in loads:
        name = f"{a.csv_dir}/hp_{a.geometry_tag}_load_{load:g}N_updown.csv"
        up, down = read_curve(name)
        pressures = pressures or [r[0] for r in up]
        split = classify(up, down, load)
        if split is None:
            sys.exit(f"{name}: the falling half is incomplete (fe_airbag hp --and-back 1)")
        pairs, apart, s_open, s_close = split
        snaps["open"] += s_open
        snaps["close"] += s_close
        for (u, d), sep in zip(pairs, apart):
            for state, branches in ((u, ("folded",) if sep else ("folded", "open")), (d, ("open",) if sep else ())):
                if not state[3]:
                    continue
                for b in branches:
                    by_branch[b].setdefault(round(state[0]), {}).setdefault(load, []).append((state[1], state[2]))
    out = {}
    for b, at_p in by_branch.items():
        cols = []
        for p in pressures:
            pts = [(np.mean([s[0] for s in st]), load, np.mean([s[1] for s in st]))
                   for load, st in at_p.get(round(p), {}).items()]
            cols.append(column(pts, heights))
        out[b] = fill_missing(cols)
    p_top = max(pressures)
    opens, closes = thresholds(snaps["open"], 2 * p_top), thresholds(snaps["close"], 0.0)
    snap_loads = sorted(set(opens) | set(closes))
    open_pa = np.interp(snap_loads, sorted(opens), [opens[k] for k in sorted(opens)]) if opens \
        else np.full(len(snap_loads), 2 * p_top)
    close_pa = np.interp(snap_loads, sorted(closes), [closes[k] for k in sorted(closes)]) if closes \
        else np.zeros(len(snap_loads))
    close_pa = np.minimum(close_pa, open_pa - 500.0)
    write(a, heights, pressures, out, (snap_loads, open_pa, close_pa), loads, snaps)


def grid(cols, k):
    return [[float(cols[j][k][i]) for j in range(len(cols))] for i in range(len(cols[0][k]))]


def write(a, heights, pressures, out, snap, loads, snaps):
    snap_loads, open_pa, close_pa = snap
    with open(a.out, "w") as f:
        f.write("# Fold table of the FE airbag (scripts/fold_table.py; doc/cell_geometry.md).\n")
        f.write("# folded/open: rows plate heights, columns gauge pressures; volume_m3 the gas volume,\n")
        f.write("# plate_force_n the load the bag carries there. snap: the pressures at which the folded\n")
        f.write("# bag opens (rising) and the open one folds again (falling), by plate load.\n")
        f.write(f"# fit loads [N]: {','.join(f'{x:g}' for x in loads)}; snaps up {len(snaps['open'])}, "
                f"down {len(snaps['close'])}\n")
        f.write(f'description: "{a.description or a.geometry_tag}, loads {",".join(f"{x:g}" for x in loads)} N"\n')
        f.write("fold_time_s: 0.02\nsnap_width_pa: 200\n")
        f.write("snap:\n")
        f.write(f"  loads_n: [{', '.join(f'{x:.6g}' for x in snap_loads)}]\n")
        f.write(f"  open_pa: [{', '.join(f'{x:.6g}' for x in open_pa)}]\n")
        f.write(f"  close_pa: [{', '.join(f'{x:.6g}' for x in close_pa)}]\n")
        for b in ("folded", "open"):
            f.write(f"{b}:\n")
            f.write(f"  heights_m: [{', '.join(f'{h:.6g}' for h in heights)}]\n")
            f.write(f"  pressures_pa: [{', '.join(f'{p:.6g}' for p in pressures)}]\n")
            for key, k in (("volume_m3", 1), ("plate_force_n", 0)):
                f.write(f"  {key}:\n")
                for row in grid(out[b], k):
                    f.write(f"    - [{', '.join(f'{x:.6g}' for x in row)}]\n")


if __name__ == "__main__":
    main()
