"""Mesh pictures for bench/evaluate (evaluate.py and evaluate_highorder.py): a PLY file's
triangles, drawn shaded with matplotlib."""


def load_triangles(path):
    """The triangles of a PLY file as an array (triangles × 3 corners × xyz)."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersCore import vtkTriangleFilter
    from vtkmodules.vtkIOPLY import vtkPLYReader
    r = vtkPLYReader()
    r.SetFileName(path)
    t = vtkTriangleFilter()
    t.SetInputConnection(r.GetOutputPort())
    t.Update()
    pd = t.GetOutput()
    pts = vtk_to_numpy(pd.GetPoints().GetData()).astype(float)
    faces = vtk_to_numpy(pd.GetPolys().GetData()).reshape(-1, 4)[:, 1:]
    return pts[faces]


def draw_shaded(fig, position, tri, rgb, lo, hi, title, zoom):
    """Adds a 3-D axes at subplot `position` (rows, columns, index) showing the triangles in
    colour `rgb` under a two-sided headlight (from the camera: elevation 30°, azimuth −60°),
    over the box lo–hi."""
    import numpy as np
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    ax = fig.add_subplot(*position, projection="3d")
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None] + 1e-30
    el, az = np.radians(30.0), np.radians(-60.0)
    light = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    s = 0.15 + 0.85 * np.abs(n @ light)
    col = np.c_[s * rgb[0], s * rgb[1], s * rgb[2], np.ones_like(s)]
    ax.add_collection3d(Poly3DCollection(tri, facecolors=col, edgecolors="none", linewidths=0))
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo, zoom=zoom)
    ax.view_init(elev=30, azim=-60)
    ax.set_axis_off()
    ax.set_title(title, fontsize=10)
    return ax
