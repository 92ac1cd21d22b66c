"""A Magic Formula tyre's characteristic curves, the way an engineer checks a .tir file first.

Fy and Mz over the slip angle, Fx over the slip ratio, and the combined-slip loops (Fx against
Fy as the slip ratio sweeps at a held slip angle), at three loads, from the CSV that
`vdyn-server --tire-curves FILE.tir` writes (docs/formats.md, "Tyre curves").

    python3 tire_curves.py [FILE.tir] [--server vdyn-server] [--fz 2250,4500,6750] [--out tire_curves.png]
"""

import argparse
import io
import os
import subprocess

import numpy as np

from _common import figure, result

HERE = os.path.dirname(os.path.abspath(__file__))
SYNTHETIC = os.path.join(HERE, "..", "..", "..", "tires", "vdyn_synthetic_205_55R16_mf61.tir")


def curves(server, tire, fz=None):
    """The CSV of `vdyn-server --tire-curves` as a structured NumPy array (one row a point)."""
    cmd = [server, "--tire-curves", tire] + (["--fz", fz] if fz else [])
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=60).stdout
    return np.genfromtxt(io.StringIO(out), delimiter=",", names=True, dtype=None, encoding="utf-8")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tire", nargs="?", default=SYNTHETIC, help="a .tir file (default: the synthetic one)")
    ap.add_argument("--server", default="vdyn-server", help="the vdyn-server program")
    ap.add_argument("--fz", default=None, help="loads, N, e.g. 2000,4000 (default 0.5, 1, 1.5 x FNOMIN)")
    ap.add_argument("--out", default="tire_curves.png", help="the figure")
    args = ap.parse_args()
    c = curves(args.server, args.tire, args.fz)
    loads = sorted(set(c["Fz_N"].tolist()))
    plt = figure()
    fig, ax = plt.subplots(2, 2, figsize=(11, 8))
    stats = []
    for fz in loads:
        lat = c[(c["curve"] == "lateral") & (c["Fz_N"] == fz)]
        lon = c[(c["curve"] == "longitudinal") & (c["Fz_N"] == fz)]
        alpha_deg = np.degrees(lat["alpha_rad"])
        label = f"Fz {fz / 1000:.2f} kN"
        ax[0, 0].plot(alpha_deg, lat["Fy_N"] / 1000, label=label)
        ax[0, 1].plot(alpha_deg, lat["Mz_Nm"], label=label)
        ax[1, 0].plot(lon["kappa"], lon["Fx_N"] / 1000, label=label)
        # The slope at the origin (the cornering stiffness) and the peaks.
        i = np.argmin(np.abs(lat["alpha_rad"]))
        k_alpha = (lat["Fy_N"][i + 1] - lat["Fy_N"][i - 1]) / (lat["alpha_rad"][i + 1] - lat["alpha_rad"][i - 1])
        stats.append({"Fz_N": fz, "Kya_N_per_rad": float(k_alpha),
                      "mu_y": float(np.max(np.abs(lat["Fy_N"])) / fz),
                      "mu_x": float(np.max(np.abs(lon["Fx_N"])) / fz),
                      "Mz_peak_Nm": float(np.max(lat["Mz_Nm"])),
                      "Mz_peak_alpha_deg": float(alpha_deg[np.argmax(lat["Mz_Nm"])])})
    nominal = loads[len(loads) // 2]
    for alpha in sorted(set(c[c["curve"] == "combined"]["alpha_rad"].tolist())):
        comb = c[(c["curve"] == "combined") & (c["Fz_N"] == nominal) & (c["alpha_rad"] == alpha)]
        ax[1, 1].plot(comb["Fx_N"] / 1000, comb["Fy_N"] / 1000, label=f"alpha {np.degrees(alpha):.0f} deg")
    titles = [("slip angle, deg", "Fy, kN", "side force"), ("slip angle, deg", "Mz, N m", "aligning moment"),
              ("slip ratio", "Fx, kN", "longitudinal force"),
              ("Fx, kN", "Fy, kN", f"combined slip at {nominal / 1000:.2f} kN, slip ratio -0.5..0.5")]
    for a, (x, y, t) in zip(ax.flat, titles):
        a.set_xlabel(x)
        a.set_ylabel(y)
        a.set_title(t)
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"{os.path.basename(args.tire)}: Magic Formula curves (ISO-W signs, no camber)")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    result(loads=loads, curves=stats)


if __name__ == "__main__":
    main()
