"""How a law's nominal model and the simulated plant pair their joints, when they differ.

A law is designed on one model of an arm (example-robot-data's ``panda``, its URDF) and run on
another description of the same arm (MuJoCo Menagerie's ``panda.xml``, with rotor inertia and
friction): the question "what does this design do on the arm as the other model describes
it". The law's torque ``tau[i]`` drives the plant's joint ``i``, and it reads the plant's
joint ``i``: joints are matched **by order**. :func:`match_joints` checks that the pairing is
what the user means, once, at the edge: the same number of joints, the same kind of plant (a
serial model's law on a serial plant), and, with a stated map (``{model joint: plant joint}``,
``--joint-map a=b,...``), every joint named once and paired in the same order. A map that
would reorder joints is refused by name: the engines do not permute joints.

The :class:`JointMatch` is recorded in the outputs (``results.json``, the stress record).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["JointMatch", "JointMapError", "match_joints", "parse_joint_map"]


class JointMapError(ValueError):
    """A law's model and a plant whose joints cannot be paired (names the joints)."""


@dataclass(frozen=True)
class JointMatch:
    """The pairing of a law's model joints with the plant's, as checked by :func:`match_joints`.

    Attributes
    ----------
    by : {"same", "order", "map"}
        ``"same"``: the law's model is the plant; ``"order"``: i-th with i-th; ``"map"``: a
        stated map, checked to pair them in order.
    model, plant : str
        The law's model and the plant: name and source (``"panda (panda)"``).
    pairs : tuple of (str, str)
        ``(model joint, plant joint)``, base to tip.
    """

    by: str
    model: str
    plant: str
    pairs: tuple

    def to_dict(self) -> dict:
        """JSON-ready: ``by``, ``model``, ``plant``, ``pairs`` as lists."""
        return {"by": self.by, "model": self.model, "plant": self.plant,
                "pairs": [list(p) for p in self.pairs]}


def _label(plant) -> str:
    return f"{plant.name} ({plant.source})"


def match_joints(model, plant, joint_map: dict | None = None) -> JointMatch:
    """Check that a law designed on ``model`` can run on ``plant``; return the pairing.

    Parameters
    ----------
    model : Plant
        The law's nominal model.
    plant : Plant
        The simulated plant.
    joint_map : dict of str to str, optional
        ``{model joint: plant joint}`` for every joint; default: by order.

    Returns
    -------
    JointMatch

    Raises
    ------
    JointMapError
        A serial model's law on a closed chain (or the reverse), different joint counts
        (naming both lists), a map naming an unknown joint, a joint twice or not every joint,
        or pairing joints out of order.
    """
    if model is plant:
        names = tuple(model.joint_names)
        return JointMatch("same", _label(model), _label(plant), tuple(zip(names, names,
                                                                          strict=True)))
    if bool(model.loop_closures) != bool(plant.loop_closures):
        kinds = {True: "a closed chain", False: "a serial arm"}
        raise JointMapError(
            f"the law's model {model.name!r} is {kinds[bool(model.loop_closures)]} and the "
            f"plant {plant.name!r} is {kinds[bool(plant.loop_closures)]}: a law runs on a plant "
            f"of its model's kind")
    a, b = list(model.joint_names), list(plant.joint_names)
    if len(a) != len(b):
        raise JointMapError(f"the law's model {model.name!r} has {len(a)} joints ({', '.join(a)})"
                            f" and the plant {plant.name!r} {len(b)} ({', '.join(b)}): lock the "
                            f"extra joints (e.g. a gripper's) so both have the same")
    if not joint_map:
        return JointMatch("order", _label(model), _label(plant), tuple(zip(a, b, strict=True)))
    unknown = [k for k in joint_map if k not in a] + [v for v in joint_map.values()
                                                       if v not in b]
    if unknown:
        raise JointMapError(f"joint map: unknown joint {unknown[0]!r} (the law's model has "
                            f"{', '.join(a)}; the plant {', '.join(b)})")
    values = list(joint_map.values())
    twice = sorted({v for v in values if values.count(v) > 1})
    missing = [j for j in a if j not in joint_map]
    if twice or missing:
        raise JointMapError("joint map: every joint once; "
                            + (f"plant joint {twice[0]!r} is named twice" if twice else
                               f"model joint {missing[0]!r} is not mapped"))
    for i, name in enumerate(a):
        if joint_map[name] != b[i]:
            raise JointMapError(
                f"joint map: {name!r} -> {joint_map[name]!r} reorders the joints (the law's "
                f"joint {i + 1} is {name!r}, the plant's {b[i]!r}); the engines pair joints in "
                f"order, so a map may rename them but not reorder them")
    return JointMatch("map", _label(model), _label(plant), tuple(zip(a, b, strict=True)))


def parse_joint_map(text: str, name: str = "--joint-map") -> dict[str, str]:
    """``"a=b,c=d"`` -> ``{"a": "b", "c": "d"}`` (each model joint once), or ``JointMapError``."""
    out = {}
    for item in (s.strip() for s in text.split(",") if s.strip()):
        key, sep, value = (s.strip() for s in item.partition("="))
        if not sep or not key or not value or key in out:
            raise JointMapError(f"{name} expects MODEL_JOINT=PLANT_JOINT,... (each model joint "
                                f"once), got {item!r}")
        out[key] = value
    if not out:
        raise JointMapError(f"{name} is empty: give MODEL_JOINT=PLANT_JOINT,...")
    return out
