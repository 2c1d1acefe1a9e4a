"""The arms' visual geometry for the 3D scenes, by description format (URDF or MJCF).

:func:`geometry_models` reads a plant's visual and collision geometry through Pinocchio
(``buildGeomFromUrdfString`` for a URDF, ``buildGeomFromMJCF`` for an MJCF), by the format of
its description (:data:`GEOMETRY_LOADERS`), never by the kind of plant. A URDF's mesh files are
looked up beside the URDF, in example-robot-data and in the package folders given; a link whose
meshes are missing is drawn as simple shapes (sticks between its joints), with one
:class:`MissingMeshWarning` naming the files. :mod:`rrr_pin.report.viewer` draws the result.

Conventions: SI units (m); each shape's placement is in its parent joint's frame.
"""

from __future__ import annotations

import math
import os
import tempfile
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

__all__ = ["geometry_models", "moving_only", "has_mesh_files", "GEOMETRY_LOADERS",
           "MissingMeshWarning"]


class MissingMeshWarning(UserWarning):
    """Mesh files of a URDF not found (drawn as simple shapes); ``.missing`` lists them."""

    def __init__(self, message: str, missing=()):
        super().__init__(message)
        self.missing = tuple(missing)



def _urdf_dir(robot) -> Path | None:
    """Folder of the robot's URDF file, if it came from one."""
    from ..model.robots import erd_urdf_path, robot_names

    source = robot.source
    if source in robot_names() and source != "rrr":
        return erd_urdf_path(source).parent
    path = Path(source)
    return path.parent.resolve() if path.is_file() else None


def _search_dirs(robot, package_dirs) -> list[Path]:
    dirs = list(package_dirs)
    dirs += [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    base = _urdf_dir(robot)
    if base is not None:
        dirs += list(base.parents)
    return dirs


def _resolve_mesh(filename: str, base: Path | None, search_dirs: list[Path]) -> Path | None:
    """Absolute path of a URDF mesh reference, or None when no candidate file exists."""
    if filename.startswith("package://"):
        package, _, sub = filename[len("package://"):].partition("/")
        candidates = [d / package / sub for d in search_dirs]
        if base is not None:  # a folder named like the package, above the URDF
            candidates += [anc / sub for anc in (base, *base.parents) if anc.name == package]
    elif filename.startswith("file://"):
        candidates = [Path(filename[len("file://"):])]
    else:
        path = Path(filename)
        candidates = [path] if path.is_absolute() or base is None else [base / path]
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    return None


def _stick_shapes(root: ET.Element, link: str, radius: float) -> list[ET.Element]:
    """Cylinders from a link's frame to each child joint (a box for a terminal link)."""
    shapes = []
    for joint in root.findall("joint"):
        parent = joint.find("parent")
        if parent is None or parent.get("link") != link:
            continue
        origin = joint.find("origin")
        xyz = np.array([float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None
                                           else "0 0 0").split()])
        length = float(np.linalg.norm(xyz))
        if length < 1e-9:
            continue
        u = xyz / length  # rotate the cylinder's z onto u: pitch, then yaw
        rpy = f"0 {math.acos(max(-1.0, min(1.0, u[2])))!r} {math.atan2(u[1], u[0])!r}"
        center = " ".join(repr(float(c)) for c in xyz / 2.0)
        shapes.append(ET.fromstring(
            f'<g><origin xyz="{center}" rpy="{rpy}"/><geometry><cylinder radius="{radius!r}" '
            f'length="{length!r}"/></geometry></g>'))
    if not shapes:
        side = 2.0 * radius
        shapes.append(ET.fromstring(
            f'<g><origin xyz="0 0 0" rpy="0 0 0"/><geometry><box size="{side!r} {side!r} '
            f'{side!r}"/></geometry></g>'))
    return shapes


def _geometry_urdf(robot, package_dirs) -> tuple[str, list[str]]:
    """Rewrite the URDF with absolute mesh paths; missing meshes become simple shapes.

    Returns the URDF text and the list of mesh references that could not be found.
    """
    root = ET.fromstring(robot.urdf)
    base = _urdf_dir(robot)
    search = _search_dirs(robot, package_dirs)
    reach = sum(float(np.linalg.norm([float(v) for v in o.get("xyz", "0 0 0").split()]))
                for o in root.findall("joint/origin"))
    radius = max(0.02 * reach, 0.005)
    missing: list[str] = []
    for link in root.findall("link"):
        for kind in ("visual", "collision"):
            lost = False
            for element in link.findall(kind):
                mesh = element.find("geometry/mesh")
                if mesh is None:
                    continue
                path = _resolve_mesh(mesh.get("filename", ""), base, search)
                if path is None:
                    missing.append(mesh.get("filename", ""))
                    link.remove(element)
                    lost = True
                else:
                    mesh.set("filename", str(path))
            if lost:
                for shape in _stick_shapes(root, link.get("name"), radius):
                    element = ET.SubElement(link, kind)
                    element.extend(list(shape))
    return ET.tostring(root, encoding="unicode"), sorted(set(missing))


def _mjcf_geometry(plant, package_dirs) -> tuple[pin.GeometryModel, pin.GeometryModel,
                                                 list[str]]:
    """Visual and collision geometry of a plant described by MJCF, through Pinocchio.

    Read from the MJCF file itself when the plant came from one (its mesh paths stay relative
    to it), else from the plant's MJCF text in a temporary file.
    """
    source = Path(plant.source)
    if source.is_file():
        return tuple(pin.buildGeomFromMJCF(plant.model, str(source), kind)
                     for kind in (pin.GeometryType.VISUAL, pin.GeometryType.COLLISION)) + ([],)
    fd, tmp = tempfile.mkstemp(suffix=".xml")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(plant.source_text()[0])
        visual = pin.buildGeomFromMJCF(plant.model, tmp, pin.GeometryType.VISUAL)
        collision = pin.buildGeomFromMJCF(plant.model, tmp, pin.GeometryType.COLLISION)
    finally:
        os.unlink(tmp)
    return visual, collision, []


def _urdf_geometry(robot, package_dirs) -> tuple[pin.GeometryModel, pin.GeometryModel,
                                                 list[str]]:
    """Visual and collision geometry of a plant described by URDF (missing meshes replaced)."""
    text, missing = _geometry_urdf(robot, package_dirs)
    if missing:
        warnings.warn(MissingMeshWarning(f"robot {robot.name!r}: mesh files not found, drawn as "
                                         f"simple shapes instead: {', '.join(missing)}",
                                         missing), stacklevel=4)
    visual = pin.buildGeomFromUrdfString(robot.model, text, pin.GeometryType.VISUAL)
    collision = pin.buildGeomFromUrdfString(robot.model, text, pin.GeometryType.COLLISION)
    return visual, collision, missing


#: The geometry loader of each description format (the suffix of ``Plant.source_text``), and
#: the format's name in the scene's legend: the viewer knows formats, never kinds of plant.
GEOMETRY_LOADERS = {".urdf": ("URDF", _urdf_geometry), ".xml": ("MJCF", _mjcf_geometry)}


def geometry_models(robot, package_dirs) -> tuple[pin.GeometryModel, pin.GeometryModel,
                                                   list[str]]:
    """Visual and collision geometry of ``robot`` by its description's format."""
    return GEOMETRY_LOADERS[robot.source_text()[1]][1](robot, package_dirs)


def moving_only(geometry: pin.GeometryModel) -> pin.GeometryModel:
    """Copy of ``geometry`` without the shapes fixed to the world (parent joint 0)."""
    out = pin.GeometryModel()
    for g in geometry.geometryObjects:
        if g.parentJoint != 0:
            out.addGeometryObject(g)
    return out


def has_mesh_files(geometry: pin.GeometryModel) -> bool:
    """Whether ``geometry`` draws mesh files (DAE, STL, OBJ) rather than primitives only."""
    return any(g.meshPath and Path(g.meshPath).suffix.lower() in (".dae", ".stl", ".obj")
               for g in geometry.geometryObjects)
