"""Draw the manipulator in the table poses of Tables 2 and 3 -> mechanism.png.

Side views in the arm plane (global y, z; x = 0, q1 = 0) with joints, the strut B-A
(body 5 barrel, body 6 rod), the tabulated centres of gravity and, for Table 2, the three
cylinders; a top view shows Table 2's slewing cylinder.  Run: python draw_mechanism.py
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import parameters  # noqa: E402

HERE = Path(__file__).resolve().parent


def side_view(ax, p: dict[str, float], title: str, cylinders: bool) -> None:  # noqa: ANN001
    """Links, joints, strut and cgs of one parameter set in the y-z plane (m)."""
    pts = parameters.loop_points(p)
    J2, C, B, A = pts["J2"], pts["C"], pts["B"], pts["A"]
    ground = min(0.0, min(p[f"cg{b}_z"] for b in range(2, 7))) - 0.3
    ax.axhline(ground, color="0.4", lw=1)
    ax.plot(
        [0, 0],
        [ground, J2[1]],
        color="tab:gray",
        lw=6,
        solid_capstyle="butt",
        label="body 2 (turns about z, q1)",
    )
    ax.plot([J2[0], C[0]], [J2[1], C[1]], color="tab:blue", lw=5, label="body 3 (q2 at J2)")
    ax.plot([J2[0], A[0]], [J2[1], A[1]], color="tab:blue", lw=5)  # boom on to A, or a bracket
    low = (p["cyl3_by"], p["cyl3_bz"]) if cylinders else C  # rocker's lower arm carries cylinder 3
    ax.plot([low[0], B[0]], [low[1], B[1]], color="tab:green", lw=4, label="body 4 (q3 at C)")
    mid = (0.45 * B[0] + 0.55 * A[0], 0.45 * B[1] + 0.55 * A[1])
    ax.plot([B[0], mid[0]], [B[1], mid[1]], color="tab:orange", lw=7, label="body 5 barrel (q4 at B)")
    ax.plot(
        [mid[0] - 0.1 * (mid[0] - B[0]), A[0]],
        [mid[1] - 0.1 * (mid[1] - B[1]), A[1]],
        color="tab:red",
        lw=3,
        label="body 6 rod (q5 slide, q6 turn; pin A)",
    )
    for name, x in pts.items():
        ax.plot(*x, "o", mfc="white", mec="k", ms=8, zorder=5)
        ax.annotate(name, x, xytext=(6, 6), textcoords="offset points", fontsize=9, weight="bold")
    for b in range(2, 7):
        cg = (p[f"cg{b}_y"], p[f"cg{b}_z"])
        ax.plot(*cg, "P", color="k", ms=7, zorder=6)
        ax.annotate(f"cg{b}", cg, xytext=(-8, -14), textcoords="offset points", fontsize=8)
    if cylinders:
        ax.plot([0, p["cyl2_ay"]], [p["cyl2_az"], p["cyl2_az"]], color="tab:gray", lw=3)  # turret bracket
        ax.plot([p["cyl3_ay"], p["cyl3_ay"]], [p["cyl3_az"], J2[1]], color="tab:blue", lw=3)  # boom bracket
        for n in (2, 3):
            a = (p[f"cyl{n}_ay"], p[f"cyl{n}_az"])
            b = (p[f"cyl{n}_by"], p[f"cyl{n}_bz"])
            ax.plot([a[0], b[0]], [a[1], b[1]], color="purple", lw=3, ls="--")
            ax.annotate(
                f"cyl{n}",
                ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2),
                xytext=(4, -12),
                textcoords="offset points",
                color="purple",
                fontsize=9,
            )
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("y (m)")
    ax.set_ylabel("z (m)")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)


def top_view(ax, p: dict[str, float]) -> None:  # noqa: ANN001
    """Table 2 from above: the slewing cylinder 1 from the ground point to the turret lever."""
    a = (p["cyl1_ax"], p["cyl1_ay"])
    b = (p["cyl1_bx"], p["cyl1_by"])
    ax.add_patch(plt.Circle((0, 0), 0.6, color="tab:gray", alpha=0.5))
    ax.plot([0, b[0]], [0, b[1]], color="tab:gray", lw=5, label="turret lever (body 2)")
    ax.plot([0, 0], [0, p["a3_y"]], color="tab:blue", lw=5, label="boom (body 3)")
    ax.plot([a[0], b[0]], [a[1], b[1]], color="purple", lw=3, ls="--", label="cyl1 (ground to lever)")
    ax.plot(*a, "s", color="k")
    ax.annotate("ground point (0, -3, 0)", a, xytext=(6, -4), textcoords="offset points", fontsize=8)
    ax.set_title("Table 2, top view (z axis = q1)", fontsize=10)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    ax.set_xlim(-2.5, 2.5)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")


def main() -> None:
    fig = plt.figure(figsize=(13, 8.5))
    grid = fig.add_gridspec(2, 3)
    ax3 = fig.add_subplot(grid[0, :2])
    side_view(ax3, parameters.table3(), "Table 3 (DC-motor arm), q = (0, 30, 300) deg, joint torques", False)
    ax3.legend(fontsize=7, loc="lower right")
    ax2 = fig.add_subplot(grid[1, :2])
    side_view(
        ax2, parameters.table2(), "Table 2 (hydraulic arm), q = (0, 0, 90) deg, cylinders 2 and 3", True
    )
    top_view(fig.add_subplot(grid[:, 2]), parameters.table2())
    fig.suptitle(
        "Manipulator of fmus/manipulator: joints J2, C, B, loop pin A; + = tabulated cg (table pose)"
    )
    fig.tight_layout()
    out = HERE / "mechanism.png"
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
