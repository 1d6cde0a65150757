"""Round-trip (reprojection) error of the lens inverses vs k1: docs/reprojection_error.{csv,png}.

Usage: python docs/make_reprojection_figure.py   (needs matplotlib for the PNG; the CSV is always written)

For each k1 in [-0.7, 0.3] (step 0.005) with k2 on the Lopez-Antequera manifold
(k2 = 0.019 k1 + 0.805 k1^2, the centre of the paper's k2 distribution), and distorted radii r_d
sampled finely on [0, R] for R = 0.5 (the frame's width edge) and R = 0.5737 (the 16:9 corner):

* roundtrip = max |P(inverse(r_d)) - r_d| (lens units = image widths), P(r) = r (1 + k1 r^2 + k2 r^4):
  how far from where it should be a distorted pixel lands after inverse then forward model;
* inverse = max |inverse(r_d) - r_u*| where r_u* is the exact root (float64 Newton to round-off):
  how far the undistorted sample point is off.

Both for the paper's Drap-Lefevre inverse and for glradial's exact inverse (Newton, float64; the
GLSL float32 version is ~1e-7). All values are width-normalised; multiply by 1920 for pixels of a
1920-wide frame.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from glradial.lens import lensfuncs  # noqa: E402
from glradial.lens.metrics import manifold_k2  # noqa: E402

RADII = {"width": 0.5, "corner": 0.5 * float(np.hypot(1.0, 9.0 / 16.0))}
COLUMNS = [
    "k1", "k2",
    "drap_roundtrip_width", "drap_roundtrip_corner", "drap_inverse_width", "drap_inverse_corner",
    "exact_roundtrip_width", "exact_roundtrip_corner", "exact_inverse_width", "exact_inverse_corner",
]


def true_inverse(r_d: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """Exact root by bisection on the increasing branch (independent of the Newton code)."""
    r_fold = min(lensfuncs.fold_radius(k1, k2), 10.0)
    lo, hi = np.zeros_like(r_d), np.full_like(r_d, r_fold)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        above = mid * lensfuncs.radial_factor(mid * mid, k1, k2) > r_d
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    return 0.5 * (lo + hi)


def table() -> list[dict[str, float]]:
    rows = []
    for k1 in np.round(np.arange(-0.7, 0.3 + 1e-9, 0.005), 6):
        k2 = float(manifold_k2(k1))
        row = {"k1": float(k1), "k2": k2}
        for name, radius in RADII.items():
            r_d = np.linspace(0.0, radius, 4001)
            truth = true_inverse(r_d, k1, k2)
            drap = lensfuncs.undistort_point_drap(np.stack([r_d, 0 * r_d], axis=-1), k1, k2)[:, 0]
            exact, valid = lensfuncs.undistort_radius_exact(r_d, k1, k2)
            assert valid.all(), (k1, k2, name)
            for method, r_u in (("drap", drap), ("exact", exact)):
                forward = r_u * lensfuncs.radial_factor(r_u * r_u, k1, k2)
                row[f"{method}_roundtrip_{name}"] = float(np.abs(forward - r_d).max())
                row[f"{method}_inverse_{name}"] = float(np.abs(r_u - truth).max())
        rows.append(row)
    return rows


def main() -> int:
    rows = table()
    csv_path = ROOT / "docs" / "reprojection_error.csv"
    with open(csv_path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: f"{row[k]:.6g}" for k in COLUMNS})
    print(f"wrote {csv_path}")
    for k1 in (-0.7, 0.3):
        row = min(rows, key=lambda r: abs(r["k1"] - k1))
        print(
            f"k1={row['k1']:+.3f} k2={row['k2']:.4f}: Drap round trip {row['drap_roundtrip_width']:.5f} (r<=0.5) "
            f"{row['drap_roundtrip_corner']:.5f} (r<=0.5737); inverse {row['drap_inverse_width']:.5f} / "
            f"{row['drap_inverse_corner']:.5f}; exact round trip {row['exact_roundtrip_corner']:.1e}"
        )
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no PNG")
        return 0
    k1 = np.array([r["k1"] for r in rows])
    floor = 1e-17  # exact values at float64 round-off are plotted at this floor
    fig, ax = plt.subplots(figsize=(8, 5), dpi=120)
    styles = {
        "drap_roundtrip_width": ("Drap-Lefevre, round trip, r ≤ 0.5 (width edge)", "C0", "-"),
        "drap_roundtrip_corner": ("Drap-Lefevre, round trip, r ≤ 0.5737 (16:9 corner)", "C0", "--"),
        "drap_inverse_width": ("Drap-Lefevre, undistorted point, r ≤ 0.5", "C1", "-"),
        "drap_inverse_corner": ("Drap-Lefevre, undistorted point, r ≤ 0.5737", "C1", "--"),
        "exact_roundtrip_corner": ("exact (Newton, float64), round trip, r ≤ 0.5737", "C2", "-"),
        "exact_inverse_corner": ("exact (Newton, float64), undistorted point, r ≤ 0.5737", "C2", ":"),
    }
    for key, (label, colour, style) in styles.items():
        ax.semilogy(k1, np.maximum([r[key] for r in rows], floor), style, color=colour, label=label)
    ax.axhline(0.002, color="k", lw=0.8)
    ax.text(-0.25, 0.0026, "0.002 (the paper's figure)", fontsize=8)
    ax.set_xlabel("k1 (k2 on the manifold 0.019 k1 + 0.805 k1²)")
    ax.set_ylabel("max error over the radii [image widths]")
    ax.set_title("Round-trip error of the lens inverse (width-normalised lens units)")
    ax.set_xlim(-0.7, 0.3)
    ax.set_ylim(floor / 2, 0.1)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    png_path = ROOT / "docs" / "reprojection_error.png"
    fig.savefig(png_path)
    print(f"wrote {png_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
