#!/usr/bin/python3
"""Checks FEBio 4.0 files against the format's rules (FEBio User Manual 4.0, sections 3.1-3.19):
FEBio is not in Debian, so organsmith's FEB files are structure-checked here, not solved.

Rules: root febio_spec version 4.0; Module first, the required sections (Module, Control,
Material, Mesh, MeshDomains) present, sections in the manual's order and not repeated; material ids
1..n; node and element ids 1..n; each element's node count matches its type, no repeated or
undefined node; NodeSets are plain id lists (4.0 rejects <node> children); every surface facet is
a face of an element, its node count matches its type, and its node order makes its normal point
out of that element (FEBio's pressure pushes against the facet normal, so a positive pressure then
pushes into the element, as in the INP); every SolidDomain names a defined material and the
Elements parts in the same order; every node_set, surface and load curve referenced is defined.
Usage: check_feb.py FILE... ; exit 0 = all pass, 1 = a rule broken (printed)."""
import sys
import xml.etree.ElementTree as ET

NPE = {"tet4": 4, "tet10": 10, "hex8": 8, "hex20": 20, "penta6": 6}
FNPE = {"tri3": 3, "tri6": 6, "quad4": 4, "quad8": 8}
ORDER = ["Module", "Globals", "Control", "Material", "Mesh", "MeshDomains", "MeshData", "MeshAdaptor", "Initial",
         "Boundary", "Loads", "Contact", "Constraints", "Rigid", "Discrete", "LoadData", "Step", "Output"]


def ints(s):
    return [int(x) for x in (s or "").replace("\n", ",").split(",") if x.strip()]


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def dot(a, b):
    return sum(a[i] * b[i] for i in range(3))


def check(path):
    err = []
    r = ET.parse(path).getroot()
    if r.tag != "febio_spec" or r.get("version") != "4.0":
        err.append("root must be <febio_spec version=\"4.0\">")
    tags = [c.tag for c in r]
    for req in ["Module", "Control", "Material", "Mesh", "MeshDomains"]:
        if req not in tags:
            err.append("missing section " + req)
    if not tags or tags[0] != "Module":
        err.append("Module must come first")
    idx = [ORDER.index(t) for t in tags if t in ORDER]
    if idx != sorted(idx):
        err.append("sections out of the manual's order: %s" % tags)
    if len(set(tags)) != len(tags):
        err.append("a section appears twice")
    mats = {m.get("name") for m in r.find("Material")}
    mids = [int(m.get("id")) for m in r.find("Material")]
    if mids != list(range(1, len(mids) + 1)):
        err.append("material ids are not 1..n")
    mesh = r.find("Mesh")
    xyz = {}
    for block in mesh.findall("Nodes"):
        for n in block:
            xyz[int(n.get("id"))] = [float(v) for v in n.text.split(",")]
    if sorted(xyz) != list(range(1, len(xyz) + 1)):
        err.append("node ids are not 1..n")
    parts, eids, faces = [], [], {}
    for block in mesh.findall("Elements"):
        t, name = block.get("type"), block.get("name")
        parts.append(name)
        if not name:
            err.append("an Elements block has no name")
        for e in block:
            c = ints(e.text)
            eids.append(int(e.get("id")))
            if len(c) != NPE.get(t, -1):
                err.append("element %s: %d nodes for %s" % (e.get("id"), len(c), t))
                continue
            if len(set(c)) != len(c) or not set(c) <= xyz.keys():
                err.append("element %s repeats a node or names an undefined one" % e.get("id"))
                continue
            if t in ("tet4", "tet10"):
                a, b, cc, d = (xyz[c[k]] for k in range(4))
                if dot(cross(sub(b, a), sub(cc, a)), sub(d, a)) <= 0:
                    err.append("element %s is inverted" % e.get("id"))
                for f in ((0, 1, 2), (0, 3, 1), (1, 3, 2), (2, 3, 0)):
                    faces[frozenset(c[k] for k in f)] = c
    if eids != list(range(1, len(eids) + 1)):
        err.append("element ids are not 1..n across the Elements blocks")
    nsets, surfs = {}, {}
    for s in mesh.findall("NodeSet"):
        if len(s):
            err.append("NodeSet %s has child tags (FEBio 3 syntax; 4.0 takes an id list)" % s.get("name"))
        ids = ints(s.text)
        nsets[s.get("name")] = ids
        if not set(ids) <= xyz.keys():
            err.append("NodeSet %s names an undefined node" % s.get("name"))
    for s in mesh.findall("Surface"):
        surfs[s.get("name")] = s
        for k, f in enumerate(s, 1):
            c = ints(f.text)
            if f.tag not in FNPE or len(c) != FNPE[f.tag]:
                err.append("surface %s facet %d: %s with %d nodes" % (s.get("name"), k, f.tag, len(c)))
                continue
            el = faces.get(frozenset(c[:3]))
            if el is None:
                err.append("surface %s facet %d is no element's face" % (s.get("name"), k))
                continue
            opposite = next(v for v in el[:4] if v not in c[:3])
            nrm = cross(sub(xyz[c[1]], xyz[c[0]]), sub(xyz[c[2]], xyz[c[0]]))
            if dot(nrm, sub(xyz[opposite], xyz[c[0]])) >= 0:
                err.append("surface %s facet %d: normal points into its element" % (s.get("name"), k))
    doms = [d.get("name") for d in r.find("MeshDomains")]
    for d in r.find("MeshDomains"):
        if d.get("mat") not in mats:
            err.append("domain %s: material %s is not defined" % (d.get("name"), d.get("mat")))
    if doms != parts:
        err.append("MeshDomains %s do not follow the Elements blocks %s" % (doms, parts))
    # Materials FEBio takes by their parameters: every one of the type's parameters, in range.
    for m in r.find("Material"):
        if m.get("type") == "Fung-ortho-compressible":
            p = {}
            for k in ["E1", "E2", "E3", "G12", "G23", "G31", "v12", "v23", "v31", "c", "k"]:
                if m.find(k) is None:
                    err.append("material %s: Fung-ortho-compressible needs %s" % (m.get("name"), k))
                else:
                    p[k] = float(m.find(k).text)
            if len(p) == 11:
                if min(p["E1"], p["E2"], p["E3"], p["c"], p["k"]) <= 0:
                    err.append("material %s: E1, E2, E3, c and k must be positive" % m.get("name"))
                if (p["v12"] > (p["E1"] / p["E2"]) ** 0.5 or p["v23"] > (p["E2"] / p["E3"]) ** 0.5
                        or p["v31"] > (p["E3"] / p["E1"]) ** 0.5):
                    err.append("material %s: Poisson's ratios FEBio refuses" % m.get("name"))
    # MeshData (after MeshDomains, checked above): mat_axis per element of one Elements block
    # (that block is one domain), lid 1..n in its order, a and d unit and orthogonal.
    sizes = {b.get("name"): len(b) for b in mesh.findall("Elements")}
    md = r.find("MeshData")
    for ed in (md if md is not None else []):
        name = ed.get("elem_set")
        if ed.tag != "ElementData" or ed.get("type") != "mat_axis":
            continue
        if name not in sizes:
            err.append("ElementData mat_axis: elem_set %s is no Elements block" % name)
            continue
        lids = [int(e.get("lid")) for e in ed]
        if lids != list(range(1, sizes[name] + 1)):
            err.append("ElementData mat_axis %s: lids are not 1..%d" % (name, sizes[name]))
        for e in ed:
            a = [float(v) for v in e.find("a").text.split(",")]
            d = [float(v) for v in e.find("d").text.split(",")]
            if abs(dot(a, a) - 1) > 1e-4 or abs(dot(d, d) - 1) > 1e-4 or abs(dot(a, d)) > 1e-4:
                err.append("ElementData mat_axis %s element %s: a and d are not orthonormal" % (name, e.get("lid")))
                break
    lcs = {int(l.get("id")) for l in r.iter("load_controller")}
    for el in r.iter():
        if el.get("lc") and int(el.get("lc")) not in lcs:
            err.append("load curve %s is not defined" % el.get("lc"))
        if el.get("node_set") and el.get("node_set") not in nsets:
            err.append("node_set %s is not defined" % el.get("node_set"))
        if el.tag == "surface_load" and el.get("surface") not in surfs:
            err.append("surface %s is not defined" % el.get("surface"))
    return err


failures = 0
for path in sys.argv[1:]:
    e = check(path)
    failures += len(e)
    print(path + ": " + ("OK" if not e else "\n  ".join([""] + e[:20])))
sys.exit(1 if failures else 0)
