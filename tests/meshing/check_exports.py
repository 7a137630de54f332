#!/usr/bin/python3
"""Opens every mesh organsmith exported under DIR with independent readers and checks that
they all see the same node and element counts: Debian's python3-meshio (STL, OBJ, PLY, VTU,
MSH 4.1 and 2.2, Abaqus INP), VTK's XML readers (VTP, VTU) and `gmsh -check` (MSH).
Exit 0 = all agree, 1 = a mismatch (printed), 77 = a reader is not installed."""
import glob, os, shutil, subprocess, sys

try:
    import meshio
    import vtk
except ImportError as e:
    print("missing reader:", e)
    sys.exit(77)
if shutil.which("gmsh") is None:
    print("missing reader: gmsh")
    sys.exit(77)

root = sys.argv[1]
failures = []

def cells(m, kind):
    return sum(len(b.data) for b in m.cells if b.type == kind)

for organ_dir in sorted(glob.glob(os.path.join(root, "*"))):
    if not os.path.isdir(organ_dir):
        continue
    for vtp in sorted(glob.glob(os.path.join(organ_dir, "*.vtp"))):
        stem = vtp[:-4]
        r = vtk.vtkXMLPolyDataReader(); r.SetFileName(vtp); r.Update()
        pd = r.GetOutput()
        n_pts, n_tri = pd.GetNumberOfPoints(), pd.GetNumberOfPolys()
        for ext in ("obj", "ply"):
            m = meshio.read(stem + "." + ext)
            if (len(m.points), cells(m, "triangle")) != (n_pts, n_tri):
                failures.append(f"{stem}.{ext}: meshio sees {len(m.points)} points, {cells(m, 'triangle')} triangles; VTK sees {n_pts}, {n_tri} in the VTP")
        m = meshio.read(stem + ".stl")
        if cells(m, "triangle") != n_tri:
            failures.append(f"{stem}.stl: {cells(m, 'triangle')} triangles, VTP has {n_tri}")
        print(f"{os.path.basename(stem)}: {n_pts} points, {n_tri} triangles in STL OBJ PLY VTP")
    for vtu in sorted(glob.glob(os.path.join(organ_dir, "*.vtu"))):
        stem = vtu[:-4]
        r = vtk.vtkXMLUnstructuredGridReader(); r.SetFileName(vtu); r.Update()
        ug = r.GetOutput()
        n_pts, n_tet = ug.GetNumberOfPoints(), ug.GetNumberOfCells()
        regions = ug.GetCellData().GetArray("region_id")
        if regions is None or regions.GetNumberOfTuples() != n_tet:
            failures.append(f"{vtu}: region_id cell data missing")
        for path in (vtu, stem + ".msh", stem + ".v22.msh", stem + ".inp"):
            m = meshio.read(path, file_format="abaqus" if path.endswith(".inp") else None)
            tets = cells(m, "tetra") + cells(m, "tetra10")
            if (len(m.points), tets) != (n_pts, n_tet):
                failures.append(f"{path}: meshio sees {len(m.points)} points, {tets} tets; VTK sees {n_pts}, {n_tet}")
        for path in (stem + ".msh", stem + ".v22.msh"):
            out = subprocess.run(["gmsh", "-check", path], capture_output=True, text=True)
            text = out.stdout + out.stderr
            if out.returncode != 0 or "Error" in text:
                failures.append(f"gmsh -check {path}: exit {out.returncode}\n{text[-2000:]}")
            else:
                # gmsh counts every element: the tetrahedra and the triangles of the named surfaces.
                m = meshio.read(path)
                total = n_tet + cells(m, "triangle") + cells(m, "triangle6")
                if f" {total} elements" not in text:
                    failures.append(f"gmsh -check {path}: does not report {total} elements ({n_tet} tets)\n{text[-2000:]}")
        print(f"{os.path.basename(stem)}: {n_pts} nodes, {n_tet} tets in VTU MSH4.1 MSH2.2 INP (meshio, VTK, gmsh)")

for f in failures:
    print("MISMATCH", f)
sys.exit(1 if failures else 0)
