#!/usr/bin/env python3
"""Figures of the FE airbag (doc/fe_membrane.md) from the CSVs fe_airbag writes into doc/fe.

usage: /usr/bin/python3 scripts/plot_fe.py [doc/fe] [--profiles DIR]
  --profiles DIR: mid-plane sections from the VTKs of
      fe_airbag hp --loads 10.6 --pressures-kpa 1,30,20 --vtk-all 1 --out DIR
"""
import csv
import glob
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

# Paper eq. 24 with x read as bar (doc/paper_targets.md, target 7).
EQ24 = [-4.603e5, 4.099e5, -1.349e5, 1.955e4, -9.741e2]


def eq24_mm(p_pa):
    x = np.asarray(p_pa) * 1e-5
    return sum(c * x ** (4 - i) for i, c in enumerate(EQ24))


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def col(rs, key, scale=1.0):
    return [float(r[key]) * scale for r in rs]


def verification(d):
    rs = rows(os.path.join(d, "verification.csv"))
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for shape, marker in (("sphere", "o"), ("tube", "s")):
        sub = [r for r in rs if r["shape"] == shape and r["converged"] == "1"]
        res = sorted({int(r["resolution"]) for r in sub})
        finest = [r for r in sub if int(r["resolution"]) == res[-1]]
        ax[0].plot(col(finest, "stretch"), col(finest, "p_exact_pa", 1e-3), "-", label=f"{shape}: closed form")
        ax[0].plot(col(finest, "stretch"), col(finest, "p_fe_pa", 1e-3), marker, mfc="none", label=f"{shape}: FE ({finest[0]['elements']} tri)")
        n = [int(next(r for r in sub if int(r["resolution"]) == k)["elements"]) for k in res]
        err = [max(abs(float(r["rel_error"])) for r in sub if int(r["resolution"]) == k) * 100 for k in res]
        ax[1].loglog(n, err, marker + "-", label=shape)
    ax[0].set_xlabel("stretch [-]")
    ax[0].set_ylabel("gauge pressure [kPa]")
    ax[0].set_title("Yeoh balloon (R 50 mm) and tube (axial stretch 1), t 0.5 mm")
    ax[0].legend(fontsize=8)
    ax[1].axhline(1.0, color="k", lw=0.8, ls="--")
    ax[1].set_xlabel("triangles")
    ax[1].set_ylabel("max |p_FE / p_exact - 1| [%]")
    ax[1].set_title("mesh convergence (1 % line dashed)")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(os.path.join(d, "verification.png"), dpi=110)


def height_vs_pressure(d):
    reduced = rows(os.path.join(d, "reduced_hp.csv"))
    loads = sorted({float(r["load_n"]) for r in reduced})
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), sharey=False)
    for ax, geom in zip(axes, ("pillows", "gusseted")):
        for i, load in enumerate(loads):
            color = f"C{i}"
            path = os.path.join(d, f"hp_{geom}_n12_load_{load:g}N.csv")
            if os.path.exists(path):
                rs = [r for r in rows(path) if r["converged"] == "1"]
                ax.plot(col(rs, "p_gauge_pa", 1e-3), col(rs, "h_m", 1e3), "o-", color=color, ms=3, label=f"FE {load:g} N")
            red = [r for r in reduced if float(r["load_n"]) == load and r["converged"] == "1"]
            ax.plot(col(red, "p_gauge_pa", 1e-3), col(red, "h_m", 1e3), "--", color=color, lw=1, label=f"reduced {load:g} N")
        ps = [10e3 + i * 250 for i in range(73)]
        ax.plot([p * 1e-3 for p in ps], [eq24_mm(p) for p in ps], "k-", lw=2, label="paper eq. 24 (x in bar), 10.4 N")
        ax.axvspan(10, 22, color="grey", alpha=0.12, label="fig. 4 span 10-22 kPa")
        ax.set_xlabel("gauge pressure [kPa]")
        ax.set_ylabel("plate height [mm]")
        ax.set_title(f"h(p): FE {geom} vs reduced model")
        ax.set_ylim(0, 300 if geom == "gusseted" else 200)
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(os.path.join(d, "hp_compare.png"), dpi=110)


def mesh_convergence(d):
    fig, ax = plt.subplots(figsize=(6, 4))
    for path in sorted(glob.glob(os.path.join(d, "mesh_n*", "hp_pillows_n*_load_10.6N.csv"))):
        n = path.split("_n")[-1].split("_")[0]
        rs = [r for r in rows(path) if r["converged"] == "1"]
        ax.plot(col(rs, "p_gauge_pa", 1e-3), col(rs, "h_m", 1e3), "o-", ms=3, label=f"{n} elements per side")
    ax.set_xlabel("gauge pressure [kPa]")
    ax.set_ylabel("plate height [mm]")
    ax.set_title("FE pillows, 10.6 N: three meshes")
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(d, "mesh_convergence.png"), dpi=110)


def transients(d):
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.4))
    for path in sorted(glob.glob(os.path.join(d, "transient_*_load_*N.csv"))):
        rs = rows(path)
        parts = os.path.basename(path)[:-4].split("_")
        label = f"FE {parts[1]} {parts[-1]}"
        ax[0].plot(col(rs, "t_s"), col(rs, "h_m", 1e3), label=label)
        ax[1].plot(col(rs, "t_s"), col(rs, "p_gauge_pa", 1e-3), label=label)
    for path in sorted(glob.glob(os.path.join(d, "reduced_transient_load_0.6N_*.csv"))):
        rs = rows(path)
        ax[0].plot(col(rs, "t_s"), col(rs, "h_m", 1e3), "--", label="reduced model")
        ax[1].plot(col(rs, "t_s"), col(rs, "p_gauge_pa", 1e-3), "--", label="reduced model")
    ax[0].axhline(150, color="k", lw=0.8, ls=":", label="paper: ~150 mm at 5.5 s")
    ax[0].set_ylabel("plate height [mm]")
    ax[1].set_ylabel("gauge pressure [kPa]")
    for a in ax:
        a.set_xlabel("time [s]")
        a.legend(fontsize=8)
    ax[0].set_title("inflation with the paper-shaped inflow (reduced: unloaded)")
    fig.tight_layout()
    fig.savefig(os.path.join(d, "transient_unloaded.png"), dpi=110)


def main():
    args = sys.argv[1:]
    if "--profiles" in args:
        i = args.index("--profiles")
        src = args[i + 1]
        del args[i:i + 2]
        d = args[0] if args else "doc/fe"
        base = os.path.join(src, "hp_pillows_n12_load_10.6N_p")
        profiles([base + k + "hPa.vtk" for k in ("56", "86", "102", "208")],
                 os.path.join(d, "profiles_pillows_10.6N.png"), "FE pillows under 10.6 N: mid-plane sections (y = 50 mm)")
        print("plotted profiles")
    d = args[0] if args else "doc/fe"
    for name, fn in (("verification", verification), ("h(p)", height_vs_pressure), ("mesh", mesh_convergence),
                     ("transient", transients)):
        try:
            fn(d)
            print("plotted", name)
        except (OSError, StopIteration, IndexError, ValueError) as e:
            print(f"skipped {name}: {e}")
    for path in sorted(glob.glob(os.path.join(d, "transient_*N.csv"))):
        for t, h, drop, peak in pressure_dips(path):
            print(f"{os.path.basename(path)}: pressure dip {drop:.2f} kPa from {peak:.2f} kPa at {t:.2f} s, h {h:.1f} mm")




def pressure_dips(path, min_kpa=1.0, min_drop_kpa=0.2):
    """Drops of the gauge pressure below its running maximum while air flows in: (t, h, drop)."""
    rs = rows(path)
    dips, run_max, start = [], 0.0, None
    for r in rs:
        p, t = float(r["p_gauge_pa"]) * 1e-3, float(r["t_s"])
        if p >= run_max:
            if start is not None and start[2] >= min_drop_kpa:
                dips.append(start)
            run_max, start = p, None
        elif run_max >= min_kpa and float(r["inflow_kg_s"]) > 0:
            drop = run_max - p
            if start is None or drop > start[2]:
                start = (t, float(r["h_m"]) * 1e3, drop, run_max)
    if start is not None and start[2] >= min_drop_kpa:
        dips.append(start)
    return dips


def read_vtk_points(path):
    """Node positions and triangles of a legacy VTK file written by fe_airbag."""
    with open(path) as f:
        lines = f.read().split("\n")
    i = next(k for k, l in enumerate(lines) if l.startswith("POINTS"))
    n = int(lines[i].split()[1])
    pts = [tuple(map(float, lines[i + 1 + k].split())) for k in range(n)]
    j = next(k for k, l in enumerate(lines) if l.startswith("POLYGONS"))
    m = int(lines[j].split()[1])
    tris = [tuple(map(int, lines[j + 1 + k].split()[1:])) for k in range(m)]
    return pts, [t for t in tris if len(t) == 3]


def section(pts, tris, y0):
    """Segments where the plane y = y0 cuts the triangles: [(x1, z1, x2, z2)]."""
    segs = []
    for t in tris:
        cut = []
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            pa, pb = pts[a], pts[b]
            if (pa[1] - y0) * (pb[1] - y0) < 0:
                s = (y0 - pa[1]) / (pb[1] - pa[1])
                cut.append((pa[0] + s * (pb[0] - pa[0]), pa[2] + s * (pb[2] - pa[2])))
        if len(cut) == 2:
            segs.append((cut[0][0], cut[0][1], cut[1][0], cut[1][1]))
    return segs


def profiles(files, out, title):
    fig, ax = plt.subplots(figsize=(7, 5))
    for i, path in enumerate(files):
        pts, tris = read_vtk_points(path)
        label = os.path.basename(path).split("_p")[-1].replace("hPa.vtk", "")
        for k, (x1, z1, x2, z2) in enumerate(section(pts, tris, 0.0501)):
            ax.plot([x1 * 1e3, x2 * 1e3], [z1 * 1e3, z2 * 1e3], color=f"C{i}", lw=1.2,
                    label=f"{float(label) / 10:.1f} kPa" if k == 0 else None)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    main()
