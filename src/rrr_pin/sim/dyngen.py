r"""Generator of straight-line C dynamics with the plant's parameters as runtime inputs.

Hand-written (a developer tool; ``scripts/gen_dynamics.py`` writes and ``--check``\ s the committed
files). Why not CppADCodeGen, as for ``codegen_rrr.c``: the cmeel build of the Pinocchio codegen
path takes about 4 min of CPU and 5 GB of RAM per model, it records the tape for fixed
numbers, and its generated code is scalar. This generator walks the kinematic *structure* (joint
types and tree) and emits, per structure, plain C whose inputs are a parameter vector (see
:func:`parameter_layout`), the state and the torque, and which evaluates ``B`` plants at once,
structure-of-arrays (input ``x[k * B + b]`` is entry ``k`` of plant ``b``):

* ``<name>_crba``: joint-space inertia ``M(q)`` (full, row-major), composite rigid bodies;
* ``<name>_nle``: ``nonLinearEffects(q, v)`` = RNEA(q, v, 0) with gravity;
* ``<name>_gravity``: ``G(q)`` = RNEA(q, 0, 0);
* ``<name>_fd``: forward dynamics ``qdd = M(q)^{-1} (tau - nle(q, v))``, from the same CRBA and
  RNEA with an unrolled ``L D L^T`` solve. Pinocchio's ABA computes the same ``qdd`` by another
  algorithm; ``tests/test_batched.py`` compares the two.

Conventions are Pinocchio's: spatial motion ``(linear, angular)``, joint frames after the joint,
``liMi = jointPlacement * R_axis(q)``, the spatial inertia ``(m, c, I_c)`` of each body in its
joint frame, ``a_0 = -gravity``, armature added to ``M``'s diagonal. Every operation is scalar IEEE
arithmetic on one plant; the batched loop carries no operation across plants, and the C is
compiled with ``-ffp-contract=off``, so a plant's numbers do not depend on the batch it is in
(vector and scalar lanes round alike).

Supported joints: revolute about x, y or z (``JointModelRX``, ``RY``, ``RZ``) in any tree;
anything else is not a generated structure.
"""

from __future__ import annotations

import numpy as np

__all__ = ["JOINT_AXES", "PER_JOINT", "structure", "parameter_layout", "parameters",
           "generate"]

#: Joint types the generator handles: the axis (0, 1, 2) of the revolute joint.
JOINT_AXES = {"JointModelRX": 0, "JointModelRY": 1, "JointModelRZ": 2}

#: Parameters per joint: placement rotation (row-major) and translation, mass, lever, inertia
#: at the centre of mass (xx, xy, yy, xz, yz, zz), armature.
PER_JOINT = 9 + 3 + 1 + 3 + 6 + 1


def structure(model) -> str:
    """Return the kinematic structure of a ``pinocchio.Model``: joint types and parents.

    E.g. ``"RZ@0,RZ@1,RZ@2"`` for a 3-joint chain; one entry per moving joint, ``RX``/``RY``/
    ``RZ`` for the supported revolute joints and the full Pinocchio name otherwise (never a
    generated structure then).
    """
    out = []
    for i in range(1, model.njoints):
        kind = model.joints[i].shortname()
        tag = kind.replace("JointModel", "") if kind in JOINT_AXES else kind
        out.append(f"{tag}@{model.parents[i]}")
    return ",".join(out)


def parameter_layout(nq: int) -> list[str]:
    """Names of the entries of the parameter vector of an ``nq``-joint structure, in order.

    ``g_x, g_y, g_z`` (gravity, linear part [m/s^2]), then per joint ``j`` (1-based):
    ``R{j}_rc`` (placement rotation in the parent joint frame, row ``r`` column ``c``),
    ``p{j}_x..z`` [m], ``m{j}`` [kg], ``c{j}_x..z`` (centre of mass in the joint frame [m]),
    ``I{j}_xx, xy, yy, xz, yz, zz`` (about the centre of mass [kg m^2]), ``arm{j}`` [kg m^2].
    """
    names = ["g_x", "g_y", "g_z"]
    for j in range(1, nq + 1):
        names += [f"R{j}_{r}{c}" for r in range(3) for c in range(3)]
        names += [f"p{j}_{a}" for a in "xyz"] + [f"m{j}"] + [f"c{j}_{a}" for a in "xyz"]
        names += [f"I{j}_{a}" for a in ("xx", "xy", "yy", "xz", "yz", "zz")] + [f"arm{j}"]
    return names


def parameters(model) -> np.ndarray:
    """Return the parameter vector of a model, shape (3 + 23 nq,) (:func:`parameter_layout`)."""
    out = [np.asarray(model.gravity.linear, dtype=float)]
    for i in range(1, model.njoints):
        M, Y = model.jointPlacements[i], model.inertias[i]
        I = Y.inertia
        out += [M.rotation.reshape(-1), M.translation, [Y.mass], Y.lever,
                [I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2]],
                [model.armature[i - 1]]]
    return np.concatenate([np.asarray(a, dtype=float).reshape(-1) for a in out])


class _Emitter:
    """Straight-line C: scalar expressions, exact zeros and ones folded away at generation."""

    def __init__(self):
        self.lines: list[str] = []
        self.n = 0

    def let(self, expr: str) -> str:
        if expr in ("0", "1") or expr.replace("_", "").isalnum() and not expr[0].isdigit():
            return expr
        name = f"t{self.n}"
        self.n += 1
        self.lines.append(f"      const double {name} = {expr};")
        return name

    @staticmethod
    def _neg(a: str) -> str:
        if a == "0":
            return "0"
        return a[1:] if a.startswith("-") else f"-{a}"

    def add(self, *terms) -> str:
        # terms: (sign, expr); zeros dropped; left to right, as written.
        keep = [(s, e) for s, e in terms if e != "0"]
        if not keep:
            return "0"
        s0, e0 = keep[0]
        out = e0 if s0 > 0 else self._neg(e0)
        for s, e in keep[1:]:
            out = f"{out} {'+' if s > 0 else '-'} {e}"
        return self.let(out)

    def mul(self, a: str, b: str) -> str:
        if a == "0" or b == "0":
            return "0"
        if a == "1":
            return b
        if b == "1":
            return a
        if a.startswith("-") and b.startswith("-"):
            return self.let(f"{a[1:]} * {b[1:]}")
        if a.startswith("-"):
            return self.let(f"-({a[1:]} * {b})")
        if b.startswith("-"):
            return self.let(f"-({a} * {b[1:]})")
        return self.let(f"{a} * {b}")

    def dot(self, a, b) -> str:
        return self.add(*[(1, self.mul(x, y)) for x, y in zip(a, b, strict=True)])

    def cross(self, a, b):
        return [self.add((1, self.mul(a[1], b[2])), (-1, self.mul(a[2], b[1]))),
                self.add((1, self.mul(a[2], b[0])), (-1, self.mul(a[0], b[2]))),
                self.add((1, self.mul(a[0], b[1])), (-1, self.mul(a[1], b[0])))]

    def vadd(self, a, b):
        return [self.add((1, x), (1, y)) for x, y in zip(a, b, strict=True)]

    def vsub(self, a, b):
        return [self.add((1, x), (-1, y)) for x, y in zip(a, b, strict=True)]

    def scale(self, s, a):
        return [self.mul(s, x) for x in a]

    def matvec(self, R, a):
        return [self.dot(R[r], a) for r in range(3)]

    def matTvec(self, R, a):
        return [self.dot([R[0][c], R[1][c], R[2][c]], a) for c in range(3)]


def _axis_rotation(axis: int, c: str, s: str):
    """R_axis(q) as 3 x 3 expressions of ``c = cos q``, ``s = sin q``."""
    ms = f"-{s}"
    if axis == 0:
        return [["1", "0", "0"], ["0", c, ms], ["0", s, c]]
    if axis == 1:
        return [[c, "0", s], ["0", "1", "0"], [ms, "0", c]]
    return [[c, ms, "0"], [s, c, "0"], ["0", "0", "1"]]


def _kinematics(em: _Emitter, axes):
    """Per joint: rotation R (3 x 3) and translation p of liMi, from the parameters."""
    Rs, ps = [], []
    for j, axis in enumerate(axes):
        o = 3 + PER_JOINT * j
        Rp = [[f"P({o + 3 * r + cc})" for cc in range(3)] for r in range(3)]
        Rq = _axis_rotation(axis, f"C({j})", f"S({j})")
        R = [[em.add(*[(1, em.mul(Rp[r][k], Rq[k][cc])) for k in range(3)]) for cc in range(3)]
             for r in range(3)]
        Rs.append(R)
        ps.append([f"P({o + 9 + a})" for a in range(3)])
    return Rs, ps


def _inertia(j: int):
    o = 3 + PER_JOINT * j + 12
    m = f"P({o})"
    c = [f"P({o + 1 + a})" for a in range(3)]
    xx, xy, yy, xz, yz, zz = (f"P({o + 4 + a})" for a in range(6))
    return m, c, [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]


def _rnea(em: _Emitter, axes, parents, with_v: bool):
    """Emit tau = RNEA(q, v, 0) (with_v) or RNEA(q, 0, 0); returns the n torque expressions."""
    n = len(axes)
    Rs, ps = _kinematics(em, axes)
    zero = ["0", "0", "0"]
    g = ["P(0)", "P(1)", "P(2)"]
    v = {0: (zero, zero)}
    a = {0: ([em._neg(x) for x in g], zero)}
    f = {}
    for j in range(n):
        i, lam = j + 1, parents[j]
        R, p = Rs[j], ps[j]
        vl, wl = v[lam]
        al, bl = a[lam]
        e = ["0", "0", "0"]
        qd = f"V({j})" if with_v else "0"
        e[axes[j]] = qd
        # motion to child frame: w = R^T w_lam; lin = R^T (v_lam - p x w_lam)
        w_i = em.vadd(em.matTvec(R, wl), e)
        v_i = em.matTvec(R, em.vsub(vl, em.cross(p, wl)))
        b_i = em.matTvec(R, bl)
        a_i = em.matTvec(R, em.vsub(al, em.cross(p, bl)))
        # + v_i x (S qd): linear v_i x e, angular w_i x e
        a_i = em.vadd(a_i, em.cross(v_i, e))
        b_i = em.vadd(b_i, em.cross(w_i, e))
        v[i], a[i] = (v_i, w_i), (a_i, b_i)
        m, c, Ic = _inertia(j)

        def inert(lin, ang, m=m, c=c, Ic=Ic):
            fl = em.scale(m, em.vsub(lin, em.cross(c, ang)))
            nn = em.vadd(em.matvec(Ic, ang), em.cross(c, fl))
            return fl, nn

        fa, na = inert(a_i, b_i)
        fv, nv = inert(v_i, w_i)
        # f = I a + v x* (I v): lin w x fv; ang w x nv + v x fv
        f[i] = [em.vadd(fa, em.cross(w_i, fv)),
                em.vadd(na, em.vadd(em.cross(w_i, nv), em.cross(v_i, fv)))]
    tau = [None] * n
    for j in reversed(range(n)):
        i, lam = j + 1, parents[j]
        fl, nn = f[i]
        tau[j] = nn[axes[j]]
        if lam > 0:
            R, p = Rs[j], ps[j]
            fp = em.matvec(R, fl)
            np_ = em.vadd(em.matvec(R, nn), em.cross(p, fp))
            f[lam] = [em.vadd(f[lam][0], fp), em.vadd(f[lam][1], np_)]
    return tau


def _crba(em: _Emitter, axes, parents):
    """M(q) (n x n expressions, symmetric, armature on the diagonal), composite bodies."""
    n = len(axes)
    Rs, ps = _kinematics(em, axes)
    Y = {}
    for j in range(n):
        m, c, Ic = _inertia(j)
        h = em.scale(m, c)
        cc = em.dot(c, c)
        # Io = Ic + m (|c|^2 I - c c^T)
        Io = [[em.add((1, Ic[r][k]), (1, em.mul(m, cc)) if r == k else (1, "0"),
                      (-1, em.mul(h[r], c[k]))) for k in range(3)] for r in range(3)]
        Y[j + 1] = (m, h, Io)
    M = [[None] * n for _ in range(n)]
    for j in reversed(range(n)):
        i, lam = j + 1, parents[j]
        m, h, Io = Y[i]
        ax = axes[j]
        e = ["0", "0", "0"]
        e[ax] = "1"
        fl = em.cross(e, h)
        nn = [Io[r][ax] for r in range(3)]
        M[j][j] = em.add((1, nn[ax]), (1, f"P({3 + PER_JOINT * j + 22})"))
        k = j
        while parents[k] > 0:
            R, p = Rs[k], ps[k]
            fl = em.matvec(R, fl)
            nn = em.vadd(em.matvec(R, nn), em.cross(p, fl))
            k = parents[k] - 1
            M[k][j] = M[j][k] = nn[axes[k]]
        if lam > 0:
            R, p = Rs[j], ps[j]
            hr = em.matvec(R, h)
            h2 = em.vadd(hr, em.scale(m, p))
            IoRt = [[em.dot(Io[r], R[k]) for k in range(3)] for r in range(3)]  # Io R^T
            RIoRt = [[em.dot(R[r], [IoRt[0][k], IoRt[1][k], IoRt[2][k]]) for k in range(3)]
                     for r in range(3)]
            hp = em.dot(hr, p)
            pp = em.dot(p, p)
            I2 = [[None] * 3 for _ in range(3)]
            for r in range(3):
                for k in range(r, 3):
                    terms = [(1, RIoRt[r][k]), (-1, em.mul(p[r], hr[k])),
                             (-1, em.mul(hr[r], p[k])), (-1, em.mul(m, em.mul(p[r], p[k])))]
                    if r == k:
                        terms += [(1, em.mul("2.0", hp)), (1, em.mul(m, pp))]
                    I2[r][k] = I2[k][r] = em.add(*terms)
            mp, hpar, Iop = Y[lam]
            Y[lam] = (em.add((1, mp), (1, m)), em.vadd(hpar, h2),
                      [[em.add((1, Iop[r][k]), (1, I2[r][k])) for k in range(3)]
                       for r in range(3)])
    return M


def _ldlt_solve(em: _Emitter, M, rhs):
    """Emit x = M^{-1} rhs by an unrolled L D L^T factorization (M symmetric positive definite)."""
    n = len(rhs)
    L = [[None] * n for _ in range(n)]
    D, Dinv = [None] * n, [None] * n
    for j in range(n):
        D[j] = em.add((1, M[j][j]), *[(-1, em.mul(em.mul(L[j][k], L[j][k]), D[k]))
                                       for k in range(j)])
        Dinv[j] = em.let(f"1.0 / {D[j]}")
        for i in range(j + 1, n):
            s = em.add((1, M[i][j]), *[(-1, em.mul(em.mul(L[i][k], L[j][k]), D[k]))
                                       for k in range(j)])
            L[i][j] = em.mul(s, Dinv[j])
    y = [None] * n
    for i in range(n):
        y[i] = em.add((1, rhs[i]), *[(-1, em.mul(L[i][k], y[k])) for k in range(i)])
    x = [None] * n
    for i in reversed(range(n)):
        z = em.mul(y[i], Dinv[i])
        x[i] = em.add((1, z), *[(-1, em.mul(L[k][i], x[k])) for k in range(i + 1, n)])
    return x


_PROLOGUE = """\
static inline void {name}_sincos(int B, const double * __restrict q, double * __restrict s,
                                 double * __restrict c)
{{
  for (int k = 0; k < {n} * B; ++k)
  {{
    s[k] = sin(q[k]);
    c[k] = cos(q[k]);
  }}
}}
"""


def _function(name: str, fn: str, args: str, body: list[str], n: int, outs) -> str:
    lines = [f"RRR_DYN_CLONES void {name}_{fn}(int B, {args})", "{",
             f"  double s_[{n} * RRR_DYN_BMAX], c_[{n} * RRR_DYN_BMAX];",
             f"  {name}_sincos(B, q, s_, c_);",
             "#pragma omp simd", "  for (int b = 0; b < B; ++b)", "  {"]
    lines += body
    lines += [f"      out[{k} * B + b] = {e};" for k, e in outs]
    lines += ["  }", "}", ""]
    return "\n".join(lines)


def generate(name: str, model, *, source: str) -> str:
    """C source of the four batched functions for the structure of ``model``.

    Parameters
    ----------
    name : str
        C identifier prefix, e.g. ``"rrr"``.
    model : pinocchio.Model
        Only its structure (:func:`structure`) is used; no number of it enters the code.
    source : str
        Where the model came from, for the header.

    Raises
    ------
    ValueError
        A joint type the generator does not handle.
    """
    n = model.nq
    kinds = [model.joints[i].shortname() for i in range(1, model.njoints)]
    bad = [k for k in kinds if k not in JOINT_AXES]
    if bad or model.nq != model.nv or len(kinds) != n:
        raise ValueError(f"cannot generate dynamics for joints {bad or kinds}: only revolute "
                         f"joints about x, y or z ({', '.join(JOINT_AXES)})")
    axes = [JOINT_AXES[k] for k in kinds]
    parents = [int(model.parents[i]) for i in range(1, model.njoints)]
    npar = 3 + PER_JOINT * n
    st = structure(model)
    parts = [f"""\
/* GENERATED by scripts/gen_dynamics.py (rrr_pin.sim.dyngen) -- do not edit.
 * Structure-of-arrays dynamics of the structure {st}
 * (made from {source}); every number of the plant is an input: parameter vector P of
 * {npar} entries (rrr_pin.sim.dyngen.parameter_layout), x[k * B + b] = entry k of plant b.
 */
#include <math.h>

#include "dyn_common.h"

const char {name}_dyn_structure[] = "{st}";
const int {name}_dyn_nq = {n};
const int {name}_dyn_np = {npar};

#define P(k) P_[(k) * B + b]
#define S(j) s_[(j) * B + b]
#define C(j) c_[(j) * B + b]
#define V(j) v[(j) * B + b]
#define T(j) tau[(j) * B + b]
""", _PROLOGUE.format(name=name, n=n)]

    em = _Emitter()
    M = _crba(em, axes, parents)
    parts.append(_function(name, "crba", "const double * __restrict P_, const double * "
                           "__restrict q, double * __restrict out", em.lines, n,
                           [(r * n + k, M[r][k]) for r in range(n) for k in range(n)]))
    em = _Emitter()
    tau = _rnea(em, axes, parents, True)
    parts.append(_function(name, "nle", "const double * __restrict P_, const double * "
                           "__restrict q, const double * __restrict v, double * __restrict out",
                           em.lines, n, list(enumerate(tau))))
    em = _Emitter()
    tau = _rnea(em, axes, parents, False)
    parts.append(_function(name, "gravity", "const double * __restrict P_, const double * "
                           "__restrict q, double * __restrict out", em.lines, n,
                           list(enumerate(tau))))
    em = _Emitter()
    M = _crba(em, axes, parents)
    nle = _rnea(em, axes, parents, True)
    rhs = [em.add((1, f"T({j})"), (-1, nle[j])) for j in range(n)]
    x = _ldlt_solve(em, M, rhs)
    parts.append(_function(name, "fd", "const double * __restrict P_, const double * "
                           "__restrict q, const double * __restrict v, const double * "
                           "__restrict tau, double * __restrict out", em.lines, n,
                           list(enumerate(x))))
    return "\n".join(parts)
