"""3D animation of one or several arms as a self-contained HTML page, drawn by MeshCat.

A :class:`Scene` is one robot model and a list of :class:`Track` objects (a label, times and
joint trajectories, an opacity): typically the nominal arm (opaque) and the uncertain plants
(translucent ghosts) under one controller. :func:`scene_html` turns it into HTML that opens
from disk with no server and no network:

* the geometry comes from the robot's URDF through Pinocchio (``buildGeomFromUrdfString``),
  or for a closed chain (:class:`rrr_pin.model.closed_chain.ClosedChain`) from its MJCF
  (``buildGeomFromMJCF``), and is loaded into the scene by Pinocchio's own
  ``MeshcatVisualizer``: primitives, and STL, OBJ and DAE meshes;
* the scene is recorded in memory: a ``meshcat.Visualizer`` is given a recording window
  instead of its ZeroMQ server (creating a plain ``meshcat.Visualizer()`` starts a server
  subprocess and prints its URL; this module never does);
* the recorded MeshCat commands (msgpack, embedded as base64) are replayed by MeshCat's own
  viewer script (``meshcat/viewer/dist/main.min.js``, three.js), inlined into the page, the way
  MeshCat's static-HTML export does it. MeshCat's animation panel gives play, pause, reset and
  a time slider (its "Open Controls" menu, opened by default here).

Each joint frame that carries geometry is one animated node; its keyframes are the joint
placements ``oMi`` from Pinocchio's forward kinematics at the frame times, and the geometry
hangs below it at its fixed placement. Frames are resampled from each track by linear
interpolation of ``q`` and decimated to keep the page within a byte budget.

A closed chain's track gives only its actuated angles (what a closed-chain trajectory
records): at each frame the passive joints are solved from them by Newton on the loop closure
(:meth:`~rrr_pin.model.closed_chain.ClosedChain.close`), seeded from the previous frame, so
every keyframe pose closes the loop (:func:`full_configurations`).

Conventions: SI units (s, rad, m); the world frame is the robot's root frame, ``z`` up.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from .geometry import (
    GEOMETRY_LOADERS,
    geometry_models,
    has_mesh_files,
    moving_only,
)

__all__ = ["Track", "Scene", "scene_html", "scene_document", "write_scene_html",
           "camera_view", "full_configurations", "ViewerSizeError",
           "MAX_SCENE_BYTES", "CAMERA_FOV"]

#: Default byte budget of one scene's HTML document [bytes].
MAX_SCENE_BYTES = 10_000_000

#: Vertical field of view of MeshCat's default perspective camera [deg].
CAMERA_FOV = 75.0

#: Unit direction from the scene centre to the camera, world frame (front right, above).
_CAMERA_DIRECTION = np.array([1.0, -1.4, 0.8]) / np.linalg.norm([1.0, -1.4, 0.8])

#: Colours (RGB in [0, 1]) given in turn to tracks without a colour of their own and drawn
#: translucent (opaque tracks without a colour keep the URDF's or MJCF's colours).
_GHOST_COLORS = ((0.12, 0.47, 0.71), (0.17, 0.63, 0.17), (0.58, 0.40, 0.74),
                 (0.84, 0.15, 0.16), (0.09, 0.75, 0.81), (0.74, 0.74, 0.13),
                 (0.55, 0.34, 0.29), (0.89, 0.47, 0.76), (0.5, 0.5, 0.5), (1.0, 0.5, 0.05))

#: Fewest frames per second the decimation may go down to before giving up [1/s].
_MIN_FPS = 2.0


class ViewerSizeError(ValueError):
    """A scene that cannot fit its byte budget, even with its frames decimated."""


@dataclass(frozen=True, eq=False)
class Track:
    """One arm's motion to animate.

    Parameters
    ----------
    label : str
        Name shown in the viewer's scene tree and legend, e.g. ``"nominal"``, ``"plant 3"``.
    t : array-like, shape (N,)
        Times [s], strictly increasing, N >= 1.
    q : array-like, shape (N, nq)
        Joint positions [rad or m] at ``t``, finite; for a closed chain its ``nq`` actuated
        coordinates only (the passive ones are solved at each frame).
    opacity : float, default 1
        In ``(0, 1]``; below 1 the arm is drawn as a translucent ghost.
    color : tuple of 3 floats in [0, 1], optional
        RGB colour of every shape of the arm. Default: the URDF's (MJCF's) colours for an opaque
        track, a colour from a fixed palette for a translucent one.
    robot : Plant, optional
        Model to draw this track with (e.g. an uncertain plant with its own kinematics);
        default the scene's robot. Must have the scene robot's ``nq``.

    Raises
    ------
    ValueError
        Naming the field, for a bad shape, non-finite values (a diverged rollout: cut it at
        its last finite sample before drawing it), times not increasing, or an opacity or
        colour out of range.
    """

    label: str
    t: np.ndarray
    q: np.ndarray
    opacity: float = 1.0
    color: tuple[float, float, float] | None = None
    robot: object = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.label, str) or not self.label.strip():
            raise ValueError(f"Track.label must be a non-empty string, got {self.label!r}")
        t = np.array(self.t, dtype=float)
        q = np.array(self.q, dtype=float)
        if t.ndim != 1 or t.size < 1:
            raise ValueError(f"Track {self.label!r}: expected t of shape (N,) with N >= 1, "
                             f"got {t.shape}")
        if q.ndim != 2 or q.shape[0] != t.size:
            raise ValueError(f"Track {self.label!r}: expected q of shape ({t.size}, nq), "
                             f"got {q.shape}")
        if not np.all(np.isfinite(t)):
            raise ValueError(f"Track {self.label!r}: t must be finite")
        if not np.all(np.diff(t) > 0.0):
            raise ValueError(f"Track {self.label!r}: t must be strictly increasing")
        bad = ~np.all(np.isfinite(q), axis=1)
        if bad.any():
            raise ValueError(f"Track {self.label!r}: q is not finite from sample "
                             f"{int(np.argmax(bad))} (t = {t[np.argmax(bad)]!r} s); cut a "
                             f"diverged rollout at its last finite sample")
        opacity = float(self.opacity)
        if not 0.0 < opacity <= 1.0:
            raise ValueError(f"Track {self.label!r}: opacity must lie in (0, 1], got "
                             f"{self.opacity!r}")
        color = self.color
        if color is not None:
            color = tuple(float(c) for c in color)
            if len(color) != 3 or not all(0.0 <= c <= 1.0 for c in color):
                raise ValueError(f"Track {self.label!r}: color must be 3 floats in [0, 1], "
                                 f"got {self.color!r}")
        t.setflags(write=False)
        q.setflags(write=False)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "opacity", opacity)
        object.__setattr__(self, "color", color)


@dataclass(frozen=True, eq=False)
class Scene:
    """Several arms of one robot model, animated together.

    Parameters
    ----------
    title : str
        Title of the scene (e.g. the controller's name).
    robot : Plant
        Model drawn for every track without a robot of its own (:func:`rrr_pin.load_robot`).
    tracks : sequence of Track
        At least one; every ``q`` has ``robot.nq`` columns.
    package_dirs : sequence of path-like, optional
        Extra folders where ``package://NAME/...`` mesh files are looked for (as
        ``DIR/NAME/...``), besides ``ROS_PACKAGE_PATH``, the URDF's own folders and
        example-robot-data.
    path : array-like, shape (K, 3), optional
        A polyline fixed in the world frame [m], drawn as a thin grey line: e.g. the
        reference path of a tool or of a Delta's platform. K >= 2, finite.
    path_label : str, default "reference path"
        Its name in the legend.
    """

    title: str
    robot: object = field(repr=False)
    tracks: tuple[Track, ...]
    package_dirs: tuple[Path, ...] = ()
    path: np.ndarray | None = field(default=None, repr=False)
    path_label: str = "reference path"

    def __post_init__(self) -> None:
        tracks = tuple(self.tracks)
        if not tracks:
            raise ValueError(f"Scene {self.title!r}: expected at least one track, got none")
        for track in tracks:
            if not isinstance(track, Track):
                raise TypeError(f"Scene {self.title!r}: tracks must be Track objects, got "
                                f"{type(track).__name__}")
            robot = track.robot or self.robot
            if track.q.shape[1] != robot.nq:
                raise ValueError(f"Scene {self.title!r}, track {track.label!r}: q has "
                                 f"{track.q.shape[1]} columns, robot {robot.name!r} has "
                                 f"nq = {robot.nq}")
        object.__setattr__(self, "tracks", tracks)
        object.__setattr__(self, "package_dirs",
                           tuple(Path(p) for p in self.package_dirs))
        if self.path is not None:
            path = np.array(self.path, dtype=float)
            if path.ndim != 2 or path.shape[1] != 3 or path.shape[0] < 2:
                raise ValueError(f"Scene {self.title!r}: expected path of shape (K, 3) with "
                                 f"K >= 2, got {path.shape}")
            if not np.isfinite(path).all():
                raise ValueError(f"Scene {self.title!r}: path must be finite")
            path.setflags(write=False)
            object.__setattr__(self, "path", path)


# --------------------------------------------------------------------------------------------
# Recording MeshCat commands without a server.


class _RecordingWindow:
    """Stands in for ``meshcat.visualizer.ViewerWindow``: keeps the packed commands in memory.

    Floats are packed in single precision (positions to ~1e-7 relative: far below a pixel).
    """

    def __init__(self) -> None:
        self.commands: list[bytes] = []

    def send(self, command) -> None:
        import umsgpack

        self.commands.append(umsgpack.packb(command.lower(), force_float_precision="single"))


def _safe(name: str) -> str:
    """Make a MeshCat path segment of a name ('/' separates segments)."""
    return re.sub(r"[/\s]+", "_", name.strip()) or "_"


def _unique_labels(tracks) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for track in tracks:
        name = _safe(track.label)
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f"{name}_{seen[name]}")
    return out


def _frame_times(tracks, fps: float) -> np.ndarray:
    t0 = min(float(tr.t[0]) for tr in tracks)
    t1 = max(float(tr.t[-1]) for tr in tracks)
    count = int(math.floor((t1 - t0) * fps + 1e-9)) + 1
    return t0 + np.arange(count) / fps


def _resample(track: Track, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frame indices inside the track's time range and ``q`` there (linear interpolation)."""
    inside = np.flatnonzero((times >= track.t[0] - 1e-12) & (times <= track.t[-1] + 1e-12))
    if inside.size == 0:
        inside = np.array([int(np.argmin(np.abs(times - track.t[0])))])
    q = np.column_stack([np.interp(times[inside], track.t, track.q[:, j])
                         for j in range(track.q.shape[1])])
    return inside, q


def _scaled(placement: pin.SE3, scale) -> np.ndarray:
    T = np.array(placement.homogeneous)
    T[:3, :3] = T[:3, :3] @ np.diag(np.asarray(scale, dtype=float))
    return T


def task_path_points(plant, duration: float) -> tuple[np.ndarray | None, str]:
    """Return a scene's path: the plant's task path as world points [m] and its label.

    :meth:`rrr_pin.model.plant.Plant.task_points` over ``duration`` [s]; ``(None, "reference
    path")`` for a plant without one (a serial arm).
    """
    found = plant.task_points(duration)
    return (None, "reference path") if found is None else found


def full_configurations(robot, q, seed=None, *, times=None, label: str = "") -> np.ndarray:
    """Return the configurations of ``robot.model`` drawn for the samples ``q`` of a track.

    :meth:`rrr_pin.model.plant.Plant.configurations`: for a serial arm ``q`` itself; for a
    closed chain each row of actuated angles completed with the passive coordinates (Newton on
    the loop closure, seeded from the previous row's solution, the first from ``seed``,
    default the chain's ``home``).

    Parameters
    ----------
    robot : Plant
    q : array-like, shape (N, robot.nq)
        Joint positions [rad or m]; a closed chain's actuated coordinates.
    seed : array-like, shape (robot.model.nq,), optional
        Closed-chain only: the configuration Newton starts from at the first row.
    times : array-like, shape (N,), optional
        Times of the rows [s], named in a failure's message (else the row number).
    label : str, optional
        Name of the track, for the failure's message.

    Returns
    -------
    ndarray, shape (N, robot.model.nq)

    Raises
    ------
    rrr_pin.model.closed_chain.LoopClosureError, SingularConfiguration (ValueErrors)
        A row where the loop does not close, or closes at a type-II singularity; the
        message names the track, the plant and the time (or row).
    """
    def where(k):
        at = f"row {k}" if times is None else f"t = {float(times[k]):.6g} s"
        return f"{f'track {label!r}: ' if label else ''}cannot draw {robot.name!r} at {at}"

    return robot.configurations(q, seed=seed, where=where)


def _track_configurations(track: Track, robot, q: np.ndarray, times: np.ndarray
                          ) -> np.ndarray:
    return full_configurations(robot, q, times=times, label=track.label)


class _Arm:
    """One track's model, geometry and joint placements at the frame times."""

    def __init__(self, track: Track, robot, geometry: pin.GeometryModel,
                 times: np.ndarray) -> None:
        self.track, self.robot, self.geometry = track, robot, geometry
        self.joints = sorted({g.parentJoint for g in geometry.geometryObjects})
        self.frames, q = _resample(track, times)
        q = _track_configurations(track, robot, q, times[self.frames])
        self.q = q  # what is drawn: shape (frames, robot.model.nq)
        model, data = robot.model, robot.model.createData()
        self.placements = np.empty((len(self.frames), len(self.joints), 4, 4))
        for k, qk in enumerate(q):
            pin.forwardKinematics(model, data, qk)
            for m, j in enumerate(self.joints):
                self.placements[k, m] = data.oMi[j].homogeneous


def _quaternion_xyzw(R: np.ndarray) -> list[float]:
    x, y, z, w = pin.Quaternion(R).coeffs()
    return [float(x), float(y), float(z), float(w)]


def _visualizer_class():
    """Pinocchio's ``MeshcatVisualizer``, with STL files sent as indexed triangle meshes.

    Many STL files (e.g. example-robot-data's UR collision meshes) store zero facet normals,
    which MeshCat's viewer keeps, drawing the mesh black; as vertices and faces (read with
    trimesh, duplicate vertices merged) the viewer computes the normals itself, and the data
    is smaller.
    """
    import meshcat.geometry as mg
    import trimesh
    from pinocchio.visualize import MeshcatVisualizer

    class _Visualizer(MeshcatVisualizer):
        def loadMeshFromFile(self, geometry_object):  # noqa: N802 (Pinocchio's name)
            if Path(geometry_object.meshPath).suffix.lower() == ".stl":
                mesh = trimesh.load(geometry_object.meshPath, force="mesh")
                return mg.TriangularMeshGeometry(mesh.vertices, mesh.faces)
            return super().loadMeshFromFile(geometry_object)

    return _Visualizer


def _load_arms(vis, arms: list[_Arm], names: list[str], ghost_colors) -> None:
    MeshcatVisualizer = _visualizer_class()  # noqa: N806 (a class)
    for arm, name, ghost in zip(arms, names, ghost_colors, strict=True):
        viz = MeshcatVisualizer(arm.robot.model, None, arm.geometry)
        viz.initViewer(viewer=vis)
        track = arm.track
        rgb = track.color if track.color is not None else (ghost if track.opacity < 1.0
                                                           else None)
        color = None if rgb is None else [*rgb, track.opacity]
        for geom in arm.geometry.geometryObjects:
            node = f"arms/{name}/joint{geom.parentJoint}"
            viz.viewerVisualGroupName = node
            override = geom.overrideMaterial
            if color is not None:  # make DAE meshes take the colour and opacity as well
                geom.overrideMaterial = True
            viz.loadViewerGeometryObject(geom, pin.GeometryType.VISUAL, color)
            geom.overrideMaterial = override
            vis[node][_safe(geom.name)].set_transform(_scaled(geom.placement, geom.meshScale))
        for m, j in enumerate(arm.joints):  # pose at the first frame, shown before playing
            vis[f"arms/{name}/joint{j}"].set_transform(arm.placements[0, m])


def _animation_command(arms: list[_Arm], names: list[str], fps: float, play: bool):
    from meshcat.animation import Animation, AnimationClip, AnimationTrack
    from meshcat.commands import SetAnimation
    from meshcat.path import Path as MeshcatPath

    animation = Animation(default_framerate=fps)
    for arm, name in zip(arms, names, strict=True):
        frames = [int(f) for f in arm.frames]
        for m, j in enumerate(arm.joints):
            T = arm.placements[:, m]
            position = AnimationTrack("position", "vector3", frames,
                                      [[float(v) for v in T[k, :3, 3]] for k in range(len(T))])
            quaternion = AnimationTrack("quaternion", "quaternion", frames,
                                        [_quaternion_xyzw(T[k, :3, :3]) for k in range(len(T))])
            path = MeshcatPath(("meshcat", "arms", name, f"joint{j}"))
            animation.clips[path] = AnimationClip(
                tracks={"position": position, "quaternion": quaternion}, fps=fps)
    return SetAnimation(animation, play=play, repetitions=1_000_000 if play else 1)


def camera_view(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Camera position and the point it looks at, world frame [m], as :func:`scene_html` sets.

    The target is the centre of the box bounding every frame origin of every track (joints,
    links, the tool) at every time; the camera sits along a fixed direction (front right,
    above) at a distance that keeps the sphere around that box inside MeshCat's
    :data:`CAMERA_FOV` field of view. The page shifts the world by ``-target`` (the orbit
    controls turn about the page's origin), which the grid and axes follow.

    Returns
    -------
    eye : ndarray, shape (3,)
    target : ndarray, shape (3,)
    """
    return _camera(_scene_points(scene))


def _scene_points(scene: Scene) -> np.ndarray:
    """Every frame origin of every track at up to 200 instants (a closed chain's: 60) [m]."""
    points = []
    for track in scene.tracks:
        robot = track.robot or scene.robot
        data = robot.model.createData()
        # a plant with loops closes them at every point: fewer instants
        stride = max(1, len(track.t) // (60 if robot.loop_closures else 200))
        q = _track_configurations(track, robot, track.q[::stride], track.t[::stride])
        for qk in q:
            pin.framesForwardKinematics(robot.model, data, qk)
            points += [np.array(f.translation) for f in data.oMf]
    return np.array(points)


def _camera(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    low, high = points.min(axis=0), points.max(axis=0)
    target = (low + high) / 2.0
    radius = max(float(np.linalg.norm(points - target, axis=1).max()), 0.2)
    distance = 1.1 * radius / math.sin(math.radians(CAMERA_FOV / 2.0))
    return target + distance * _CAMERA_DIRECTION, target


# --------------------------------------------------------------------------------------------
# HTML.


def _meshcat_js() -> str:
    meshcat, _ = _import_meshcat()
    path = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
    return path.read_text(encoding="utf-8")


_DOCUMENT = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{title}</title>
<style>body {{margin: 0; overflow: hidden;}} #meshcat-pane {{width: 100vw; height: 100vh;
overflow: hidden;}}</style></head>
<body>
<div id="meshcat-pane"></div>
<script>{js}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
(function () {{
  function bytes(s) {{
    var raw = atob(s), out = new Uint8Array(raw.length);
    for (var i = 0; i < raw.length; i++) out[i] = raw.charCodeAt(i);
    return out;
  }}
  var commands = [{commands}];
  for (var i = 0; i < commands.length; i++) viewer.handle_command_bytearray(bytes(commands[i]));
  viewer.gui.open();
  viewer.gui.__folders["Scene"].close();
  viewer.animator.folder.open();
  requestAnimationFrame(function () {{ requestAnimationFrame(function () {{
    document.body.setAttribute("data-scene-ready", "1");
  }}); }});
}})();
</script>
</body>
</html>
"""


def _document(title: str, commands: list[bytes], js: str) -> str:
    encoded = ",\n".join(f'"{base64.b64encode(c).decode("ascii")}"' for c in commands)
    return _DOCUMENT.format(title=html.escape(title), js=js, commands=encoded)


def _import_meshcat():
    """Import meshcat (its ZeroMQ server module warns about a pyzmq deprecation on import)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat
        import meshcat.geometry as mg
    return meshcat, mg


def _record(scene: Scene, fps: float, geometry: str, play: bool,
            cache: dict) -> tuple[list[bytes], list[bytes], dict]:
    """Scene commands (static part, animation part) and facts about the recording.

    ``cache`` maps ``id(robot)`` to its geometry models, shared between calls.
    """
    meshcat, mg = _import_meshcat()

    window = _RecordingWindow()
    vis = meshcat.Visualizer(window=window)
    times = _frame_times(scene.tracks, fps)
    arms = []
    for track in scene.tracks:
        robot = track.robot or scene.robot
        if id(robot) not in cache:
            cache[id(robot)] = geometry_models(robot, scene.package_dirs)
        visual, collision, _ = cache[id(robot)]
        light = collision if collision.ngeoms and has_mesh_files(visual) else visual
        use = visual if geometry == "visual" or (geometry == "auto" and track.opacity == 1.0) \
            else light
        if track.opacity < 1.0:  # a ghost's base is the nominal one's: drawn once
            use = moving_only(use)
        arms.append(_Arm(track, robot, use, times))
    names = _unique_labels(scene.tracks)
    ghosts, k = [], 0
    for track in scene.tracks:
        ghosts.append(_GHOST_COLORS[k % len(_GHOST_COLORS)])
        k += track.opacity < 1.0 and track.color is None
    points = _scene_points(scene)
    eye, target = _camera(points)
    rel = [float(v) for v in eye - target]
    vis["/Cameras/default/rotated/<object>"].set_property(
        "position", [rel[0], rel[2], -rel[1]])  # three.js is y-up: (x, z, -y)
    shift = np.eye(4)
    shift[:3, 3] = -target
    for node in ("/meshcat", "/Axes"):
        vis[node].set_transform(shift)
    # MeshCat's 20 m grid reaches behind the camera, where software WebGL (SwiftShader) drops
    # its lines; a translucent floor of the scene's own size under the base replaces it.
    vis["/Grid"].set_property("visible", False)
    side = 2.5 * float(np.linalg.norm(eye - target)) * math.sin(math.radians(CAMERA_FOV / 2))
    vis["floor"].set_object(mg.Box([side, side, 1e-3 * side]),
                            mg.MeshLambertMaterial(color=0xd0d4dc, opacity=0.35,
                                                   transparent=True))
    floor = np.eye(4)
    # top face just below z = 0, or below the lowest frame (a Delta hangs under its base)
    floor[2, 3] = min(0.0, float(points[:, 2].min())) - 0.5e-3 * side - 1e-4 * side
    vis["floor"].set_transform(floor)
    if scene.path is not None:
        vis["path"].set_object(mg.Line(mg.PointsGeometry(scene.path.T.astype(np.float32)),
                                       mg.LineBasicMaterial(color=0x555555, linewidth=2)))
    _load_arms(vis, arms, names, ghosts)
    static = list(window.commands)
    window.commands.clear()
    vis.window.send(_animation_command(arms, names, fps, play))
    robots = {id(track.robot or scene.robot) for track in scene.tracks}
    facts = {"frames": len(times), "fps": fps, "duration": float(times[-1] - times[0]),
             "geometry": geometry,
             "missing_meshes": sorted({m for r in robots for m in cache[r][2]})}
    return static, list(window.commands), facts


def scene_document(scene: Scene, *, fps: float = 30.0, max_bytes: int = MAX_SCENE_BYTES,
                   geometry: str = "auto", play: bool = True) -> str:
    """Render the animated scene as a complete, standalone HTML document.

    Parameters
    ----------
    scene : Scene
    fps : float, default 30
        Frames per second of the animation [1/s], > 0. Lowered (decimated by an integer
        factor) when the document would exceed ``max_bytes``.
    max_bytes : int, default :data:`MAX_SCENE_BYTES`
        Byte budget of the document (UTF-8).
    geometry : {"auto", "visual", "collision"}
        Shapes to draw. ``"auto"``: the URDF's visual shapes for opaque tracks, and for
        translucent ghosts the (lighter) collision shapes when the visual ones are mesh
        files; when the meshes alone would take more than half the budget, the collision
        shapes for every track.
    play : bool, default True
        Start playing (looped) on load; otherwise the arms stand at their first frame.

    Returns
    -------
    str
        HTML with MeshCat's viewer script and the scene inlined: no network, no server.

    Raises
    ------
    ViewerSizeError (a ValueError)
        When even the first track alone at ``2`` frames per second does not fit
        ``max_bytes``. (With several tracks, the last ones are left out until the rest fits;
        the legend of :func:`scene_html` says how many were drawn.)
    ValueError
        For ``fps <= 0``, ``max_bytes <= 0`` or an unknown ``geometry``.
    """
    html_doc, _ = _scene_document(scene, fps=fps, max_bytes=max_bytes, geometry=geometry,
                                  play=play)
    return html_doc


def _scene_document(scene, *, fps, max_bytes, geometry, play):
    fps = float(fps)
    if not (math.isfinite(fps) and fps > 0.0):
        raise ValueError(f"fps must be a finite number > 0 frames/s, got {fps!r}")
    if isinstance(max_bytes, bool) or not (isinstance(max_bytes, (int, np.integer))
                                           and max_bytes > 0):
        raise ValueError(f"max_bytes must be an integer > 0, got {max_bytes!r}")
    if geometry not in ("auto", "visual", "collision"):
        raise ValueError(f"geometry must be 'auto', 'visual' or 'collision', got "
                         f"{geometry!r}")
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
    js = _meshcat_js()
    cache: dict = {}
    tracks = scene.tracks
    while True:
        drawn = scene if len(tracks) == len(scene.tracks) else dataclasses.replace(
            scene, tracks=tracks)
        doc, facts = _fit(drawn, fps, max_bytes, geometry, play, js, cache)
        if doc is not None:
            break
        if len(tracks) == 1:
            raise ViewerSizeError(
                f"scene {scene.title!r} does not fit max_bytes={max_bytes}: the geometry of "
                f"its first arm alone takes {facts['fixed']} bytes and {facts['frames']} "
                f"frames take {facts['total']} bytes even at {_MIN_FPS:g} frames/s")
        # Each arm drawn carries its own shapes: keep the first arms (the nominal first), as
        # many as the budget holds at the bytes per arm measured, at least one fewer than now.
        share = max_bytes / max(facts["total"], 1)
        tracks = tracks[:max(1, min(len(tracks) - 1, int(len(tracks) * share)))]
    facts["tracks_drawn"] = len(tracks)
    facts["tracks_total"] = len(scene.tracks)
    return doc, facts


def _fit(scene, fps, max_bytes, geometry, play, js, cache):
    """Return ``(document, facts)`` of ``scene``, its frames decimated to fit ``max_bytes``.

    ``(None, facts)``, with ``facts["fixed"]`` (the geometry's bytes) and ``facts["total"]``,
    when even :data:`_MIN_FPS` frames per second do not fit.
    """

    def size(commands):
        return len(_document(scene.title, commands, js).encode("utf-8"))

    static, anim, facts = _record(scene, fps, geometry, play, cache)
    if geometry == "auto" and size(static) > max_bytes // 2:
        light = _record(scene, fps, "collision", play, cache)
        if size(light[0]) < size(static):
            static, anim, facts = light
    stride = 1
    total, fixed = size(static + anim), size(static)
    while total > max_bytes:
        # Frames that fit, at the measured bytes per frame; decimate by an integer factor.
        per_frame = (total - fixed) / facts["frames"]
        fit = (max_bytes - fixed) / per_frame
        wanted = (fit - 1.0) / facts["duration"] if facts["duration"] > 0.0 else 0.0
        stride = max(stride + 1, math.ceil(fps / wanted) if wanted > 0.0 else math.inf)
        if not fps / stride >= _MIN_FPS:
            return None, {**facts, "fixed": fixed, "total": total}
        static, anim, facts = _record(scene, fps / stride, facts["geometry"], play, cache)
        total = size(static + anim)
    facts["bytes"] = total
    facts["fallback"] = facts["geometry"] != geometry  # "auto" fell back to "collision"
    return _document(scene.title, static + anim, js), facts


def _legend(scene: Scene, facts: dict) -> str:
    items = []
    k = 0
    for track in scene.tracks[:facts["tracks_drawn"]]:
        rgb = track.color if track.color is not None else (
            _GHOST_COLORS[k % len(_GHOST_COLORS)] if track.opacity < 1.0 else None)
        k += track.opacity < 1.0 and track.color is None
        swatch = ("#c8823c" if rgb is None else
                  "#" + "".join(f"{round(255 * c):02x}" for c in rgb))
        items.append(f'<span style="white-space:nowrap"><span style="display:inline-block;'
                     f"width:0.9em;height:0.9em;background:{swatch};opacity:"
                     f'{max(track.opacity, 0.35)};border:1px solid #555"></span> '
                     f"{html.escape(track.label)}</span>")
    source = GEOMETRY_LOADERS[scene.robot.source_text()[1]][0]
    shapes = {"auto": f"the {source}'s visual shapes (ghosts: collision shapes if lighter)",
              "visual": f"the {source}'s visual shapes",
              "collision": f"the {source}'s collision shapes"}[facts["geometry"]]
    if facts.get("fallback"):
        shapes += " (the visual meshes exceed the size budget)"
    note = (f"{facts['frames']} frames at {facts['fps']:.3g} frames/s over "
            f"{facts['duration']:.3g} s; {shapes}")
    if facts["missing_meshes"]:
        note += f"; meshes not found, drawn as simple shapes: {len(facts['missing_meshes'])}"
    if facts["tracks_drawn"] < facts["tracks_total"]:
        note += (f"; the first {facts['tracks_drawn']} of the {facts['tracks_total']} arms "
                 f"drawn (the others' shapes exceed the page's size budget; every plant is in "
                 f"the tables and figures)")
    if scene.path is not None:
        items.append(f'<span style="white-space:nowrap"><span style="display:inline-block;'
                     f'width:1.4em;height:0;border-top:2px solid #555;vertical-align:middle">'
                     f"</span> {html.escape(scene.path_label)}</span>")
    return " &nbsp; ".join(items) + f'<br><small>{html.escape(note)}. Open Controls &gt; ' \
        f"Animations: play, pause, reset, time slider; drag to orbit, scroll to zoom.</small>"


def scene_html(scene: Scene, *, fps: float = 30.0, max_bytes: int = MAX_SCENE_BYTES,
               geometry: str = "auto", play: bool = True, height: int = 520) -> str:
    """Render the animated scene as an HTML fragment (a ``<figure>``) to embed in a page.

    The scene's standalone document (:func:`scene_document`) is embedded as the ``srcdoc``
    of an ``<iframe>`` (MeshCat's viewer sizes itself to its window), with a legend below.

    Parameters
    ----------
    scene, fps, max_bytes, geometry, play
        As in :func:`scene_document`; ``max_bytes`` bounds the whole fragment.
    height : int, default 520
        Height of the viewer [CSS px].

    Returns
    -------
    str
        ``<figure class="rrr-scene">...</figure>``, self-contained.
    """
    # srcdoc escaping (& and ") grows the document a little: keep a margin for it.
    doc, facts = _scene_document(scene, fps=fps, max_bytes=int(max_bytes * 0.9),
                                 geometry=geometry, play=play)
    srcdoc = doc.replace("&", "&amp;").replace('"', "&quot;")
    return (f'<figure class="rrr-scene" data-scene-bytes="{facts["bytes"]}">'
            f"<figcaption><b>{html.escape(scene.title)}</b></figcaption>"
            f'<iframe title="{html.escape(scene.title, quote=True)}" srcdoc="{srcdoc}" '
            f'style="width:100%;height:{int(height)}px;border:1px solid #ccc"></iframe>'
            f"<figcaption>{_legend(scene, facts)}</figcaption></figure>")


def write_scene_html(path, scene: Scene, **kwargs) -> Path:
    """Write :func:`scene_document` to ``path`` (parent folders created); return the path.

    ``kwargs`` are those of :func:`scene_document`.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(scene_document(scene, **kwargs), encoding="utf-8")
    return path
