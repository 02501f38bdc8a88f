"""Draw docs/conventions.png: the course's pixel, camera and winding conventions in one small figure.

Run from the repository root: ``python docs/conventions_figure.py``.
"""
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from course.viz import pixel_grid  # noqa: E402

fig, (ax_pix, ax_cam, ax_tri) = plt.subplots(1, 3, figsize=(11, 3.6))

# 1. pixels: row 0 at the top, pixel (i, j) covers [j, j+1) × [i, i+1), centre (j + 0.5, i + 0.5)
pixel_grid(4, 3, ax=ax_pix)
ax_pix.add_patch(plt.Rectangle((2, 1), 1, 1, color="tab:orange", alpha=0.4))
ax_pix.plot([2.5], [1.5], "o", color="tab:red")
ax_pix.annotate("pixel (row 1, col 2)\ncentre (2.5, 1.5)", (2.5, 1.5), xytext=(0.2, 2.7), fontsize=8,
                arrowprops=dict(arrowstyle="->"))
ax_pix.annotate("", xy=(1.2, 0.05), xytext=(0.05, 0.05), arrowprops=dict(arrowstyle="->", color="tab:blue"))
ax_pix.annotate("", xy=(0.05, 1.2), xytext=(0.05, 0.05), arrowprops=dict(arrowstyle="->", color="tab:green"))
ax_pix.text(1.25, 0.25, "x", color="tab:blue"), ax_pix.text(0.12, 1.45, "y", color="tab:green")
ax_pix.set_title("image: row 0 at the top")

# 2. camera: OpenCV axes, +x right, +y down, +z forward (into the picture)
ax_cam.set_xlim(-1.2, 1.2), ax_cam.set_ylim(1.2, -1.2), ax_cam.set_aspect("equal"), ax_cam.axis("off")
ax_cam.annotate("", xy=(1, 0), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="tab:blue", lw=2))
ax_cam.annotate("", xy=(0, 1), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="tab:green", lw=2))
ax_cam.plot([0], [0], "o", ms=14, mfc="none", color="tab:red"), ax_cam.plot([0], [0], "x", color="tab:red")
ax_cam.text(1.02, -0.08, "+x right", color="tab:blue"), ax_cam.text(0.05, 1.12, "+y down", color="tab:green")
ax_cam.text(0.12, -0.15, "+z forward (away from you)", color="tab:red", fontsize=8)
ax_cam.set_title("camera space: x_cam = R x_world + t")

# 3. winding: counter-clockwise as seen by the viewer = front face
tri = [(0.1, 0.9), (0.9, 0.9), (0.5, 0.15)]                              # screen y down: drawn as seen
ax_tri.fill(*zip(*tri), color="tab:orange", alpha=0.4)
for k, (x, y) in enumerate(tri):
    ax_tri.annotate(f"v{k}", (x, y), xytext=(x - 0.05, y + (0.08 if y > 0.5 else -0.05)))
for a, b in zip(tri, tri[1:] + tri[:1]):
    ax_tri.annotate("", xy=b, xytext=a, arrowprops=dict(arrowstyle="->", lw=1.5))
ax_tri.set_xlim(0, 1), ax_tri.set_ylim(1.05, 0), ax_tri.set_aspect("equal"), ax_tri.axis("off")
ax_tri.set_title("front face: v0→v1→v2 counter-clockwise")

fig.tight_layout()
fig.savefig("docs/conventions.png", dpi=90)
print("wrote docs/conventions.png")
