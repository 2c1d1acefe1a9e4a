r"""Generator of straight-line C dynamics with the plant's parameters as runtime inputs.

Hand-written (a developer tool; ``scripts/gen_dynamics.py`` writes and ``--check``\ s the committed
files). Why not CppADCodeGen, as for ``codegen_rrr.c``: the cmeel build of the Pinocchio codegen
path takes about 4 min of CPU and 5 GB of RAM per model, it records the tape for fixed
numbers, and its generated code is scalar. This generator walks the kinematic *structure* (joint
types and tree) and emits, per structure, plain C whose inputs are a parameter vector (see
:func:`parameter_layout`), the state and the torque, and which evaluates ``B`` plants at once,
structure-of-arrays (input ``x[k * B + b]`` is entry ``k`` of plant ``b``):

* ``<name>_pre``: the derived vector ``D`` of a parameter vector: every parameter-only
  expression of the functions below (``m c``, the inertia at the joint origin, products of
  parameters in the parallel-axis terms, ...), evaluated once per plant, before the time loop
  (the same expressions, so the same bits as evaluating them at every call);
* ``<name>_crba``: joint-space inertia ``M(q)`` (full, row-major), composite rigid bodies;
* ``<name>_nle``: ``nonLinearEffects(q, v)`` = RNEA(q, v, 0) with gravity;
* ``<name>_gravity``: ``G(q)`` = RNEA(q, 0, 0);
* ``<name>_id``: inverse dynamics ``M(q) a + nle(q, v)`` = RNEA(q, v, a) plus the armature's
  ``armature_j a_j`` (the FL law's torque, one recursion instead of CRBA, RNEA and a product);
* ``<name>_fd``: forward dynamics ``qdd = M(q)^{-1} (tau - nle(q, v))`` by the algorithm of
  fewer operations for the structure (:func:`operation_counts`, :func:`fd_algorithm`; named by
  ``<name>_dyn_fd``): the same CRBA and RNEA with an unrolled ``L D L^T`` solve, or
  Featherstone's articulated-body algorithm; ``<name>_fd_other`` is the other one (in the
  committed files; a structure built at first use has ``_fd`` alone). Both are compared with
  Pinocchio's ``aba`` in ``tests/test_batched.py``.

The functions after ``_pre`` take ``D``. Operations are counted on the expressions the outputs
need (exact zeros and ones folded away, identical expressions named once), as the C compiler
evaluates them:
``scripts/gen_dynamics.py --counts`` prints them next to Featherstone's count for the ABA.

Conventions are Pinocchio's: spatial motion ``(linear, angular)``, joint frames after the joint,
``liMi = jointPlacement * R_axis(q)``, the spatial inertia ``(m, c, I_c)`` of each body in its
joint frame, ``a_0 = -gravity``, armature added to ``M``'s diagonal (to ``D = S^T U`` in the
ABA). Every operation is scalar IEEE arithmetic on one plant; the batched loop carries no
operation across plants, and the C is compiled with ``-ffp-contract=off``, so a plant's numbers
do not depend on the batch it is in (vector and scalar lanes round alike; the sines and cosines
of ``dyn_common.h`` go through one vector function for every angle).

Supported joints: revolute about x, y or z (``JointModelRX``, ``RY``, ``RZ``) in any tree;
anything else is not a generated structure.
"""

from __future__ import annotations

import re

import numpy as np

__all__ = ["VERSION", "JOINT_AXES", "PER_JOINT", "FD_ALGORITHMS", "structure", "parameter_layout",
           "parameters", "operation_counts", "fd_algorithm", "featherstone_aba_operations",
           "generate"]

#: The generator's release: 3 adds ``<name>_id`` (``M(q) a + nle(q, v)`` in one recursion, the FL
#: law's torque); 2 hoists the parameter-only expressions into ``<name>_pre`` (once per
#: plant) and chooses the forward-dynamics algorithm per structure by operation count
#: (:func:`operation_counts`); 1 evaluated everything at every call, by CRBA + L D L^T.
VERSION = 3

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


#: A leaf operand: a name, an input entry (``P(3)``, ``S(0)``, ...) or a number, maybe negated.
_LEAF = re.compile(r"-?(?:[A-Za-z_]\w*(?:\(\d+\))?|\d+(?:\.\d*)?)$")
_NUMBER = re.compile(r"\d+(?:\.\d*)?$")
#: Binary operators as the emitter writes them (unary minus has no space after it).
_BINARY = (" + ", " - ", " * ", " / ")


class _Hoist:
    """Parameter-only expressions of a structure's functions, computed once per plant.

    Shared by the emitters of every function of one structure: an expression whose operands are
    all parameters (``P(k)``), numbers or other hoisted names is named here (``h<k>``, one name
    per distinct expression text), and evaluated by ``<name>_pre`` before the time loop instead
    of at every call. The expression is the same text, so the same IEEE operations: hoisting
    changes no bit of any result.
    """

    def __init__(self):
        self.lines: list[tuple[str, str]] = []
        self.names: dict[str, str] = {}
        self._pure: set[str] = set()

    def pure(self, operand: str) -> bool:
        o = operand[1:] if operand.startswith("-") else operand
        return bool(_NUMBER.match(o)) or o.startswith("P(") or o in self._pure

    def let(self, expr: str) -> str:
        name = self.names.get(expr)
        if name is None:
            name = f"h{len(self.lines)}"
            self.names[expr] = name
            self._pure.add(name)
            self.lines.append((name, expr))
        return name


class _Emitter:
    """Straight-line C: scalar expressions, exact zeros and ones folded away at generation.

    Identical expressions are named once (their operands are constants: the same value); with a
    :class:`_Hoist`, parameter-only expressions go there instead.
    """

    def __init__(self, hoist: _Hoist | None = None):
        self.lines: list[str] = []
        self.temps: list[tuple[str, str]] = []
        self.names: dict[str, str] = {}
        self.n = 0
        self.hoist = hoist

    def let(self, expr: str, deps=()) -> str:
        if _LEAF.match(expr):
            return expr
        if self.hoist is not None and deps and all(self.hoist.pure(d) for d in deps):
            return self.hoist.let(expr)
        name = self.names.get(expr)
        if name is not None:
            return name
        name = f"t{self.n}"
        self.n += 1
        self.names[expr] = name
        self.temps.append((name, expr))
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
        return self.let(out, [e for _, e in keep])

    def mul(self, a: str, b: str) -> str:
        if a == "0" or b == "0":
            return "0"
        if a == "1":
            return b
        if b == "1":
            return a
        if a.startswith("-") and b.startswith("-"):
            return self.let(f"{a[1:]} * {b[1:]}", (a, b))
        if a.startswith("-"):
            return self.let(f"-({a[1:]} * {b})", (a, b))
        if b.startswith("-"):
            return self.let(f"-({a} * {b[1:]})", (a, b))
        return self.let(f"{a} * {b}", (a, b))

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


def _body(em: _Emitter, j: int):
    """Body ``j``'s inertia at its joint origin: mass, ``h = m c`` and ``Io`` (parameters only)."""
    m, c, Ic = _inertia(j)
    h = em.scale(m, c)
    cc = em.dot(c, c)
    # Io = Ic + m (|c|^2 I - c c^T)
    Io = [[em.add((1, Ic[r][k]), (1, em.mul(m, cc)) if r == k else (1, "0"),
                  (-1, em.mul(h[r], c[k]))) for k in range(3)] for r in range(3)]
    return m, h, Io


def _rnea(em: _Emitter, axes, parents, with_v: bool, with_a: bool = False):
    """Emit tau = RNEA(q, v, 0) (with_v) or RNEA(q, 0, 0); returns the n torque expressions.

    ``with_a``: RNEA(q, v, a) plus the armature's ``armature_j a_j``, i.e. ``M(q) a + nle(q, v)``
    with ``M`` as :func:`_crba` writes it (armature on the diagonal), in one recursion.
    """
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
        if with_a:  # + S qdd
            b_i[axes[j]] = em.add((1, b_i[axes[j]]), (1, f"A({j})"))
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
        if with_a:  # the rotor's inertia, as M's diagonal carries it
            tau[j] = em.add((1, tau[j]), (1, em.mul(f"P({3 + PER_JOINT * j + 22})", f"A({j})")))
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
    Y = {j + 1: _body(em, j) for j in range(n)}
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
        Dinv[j] = em.let(f"1.0 / {D[j]}", (D[j],))
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


def _rotate(em: _Emitter, R, X, symmetric: bool):
    """R X R^T (3 x 3 expressions); of a symmetric X, the upper triangle mirrored."""
    RX = [[em.dot(R[r], [X[0][k], X[1][k], X[2][k]]) for k in range(3)] for r in range(3)]
    out = [[None] * 3 for _ in range(3)]
    for r in range(3):
        for k in range(r if symmetric else 0, 3):
            out[r][k] = em.dot(RX[r], R[k])
            if symmetric:
                out[k][r] = out[r][k]
    return out


def _aba(em: _Emitter, axes, parents):
    """Emit qdd = ABA(q, v, tau): Featherstone's articulated-body algorithm, Pinocchio's passes.

    Articulated inertias are kept as blocks ``(A, B, C)`` of the symmetric 6 x 6 matrix in
    (linear, angular) order: ``f = A v + B w``, ``n = B^T v + C w``; the armature is added to
    ``D = S^T U`` as Pinocchio's ``aba`` does. Returns the n acceleration expressions.
    """
    n = len(axes)
    Rs, ps = _kinematics(em, axes)
    zero = ["0", "0", "0"]
    g = ["P(0)", "P(1)", "P(2)"]
    v, c, pA, IA = {0: (zero, zero)}, {}, {}, {}
    for j in range(n):  # pass 1: velocities, bias accelerations and forces
        i, lam = j + 1, parents[j]
        R, p = Rs[j], ps[j]
        vl, wl = v[lam]
        e = ["0", "0", "0"]
        e[axes[j]] = f"V({j})"
        w_i = em.vadd(em.matTvec(R, wl), e)
        v_i = em.matTvec(R, em.vsub(vl, em.cross(p, wl)))
        v[i] = (v_i, w_i)
        c[i] = (em.cross(v_i, e), em.cross(w_i, e))
        m, cm, Ic = _inertia(j)
        fv = em.scale(m, em.vsub(v_i, em.cross(cm, w_i)))
        nv = em.vadd(em.matvec(Ic, w_i), em.cross(cm, fv))
        pA[i] = [em.cross(w_i, fv), em.vadd(em.cross(w_i, nv), em.cross(v_i, fv))]
        mm, h, Io = _body(em, j)
        nh = [em._neg(x) for x in h]
        IA[i] = ([[mm if r == k else "0" for k in range(3)] for r in range(3)],
                 [["0", h[2], nh[1]], [nh[2], "0", h[0]], [h[1], nh[0], "0"]],  # -[h]x
                 Io)
    UD, Dinv, u = {}, {}, {}
    for j in reversed(range(n)):  # pass 2: articulated inertias and bias forces
        i, lam, ax = j + 1, parents[j], axes[j]
        A, Bm, C = IA[i]
        U = [Bm[r][ax] for r in range(3)] + [C[r][ax] for r in range(3)]
        D = em.add((1, U[3 + ax]), (1, f"P({3 + PER_JOINT * j + 22})"))
        Dinv[i] = em.let(f"1.0 / {D}", (D,))
        u[i] = em.add((1, f"T({j})"), (-1, pA[i][1][ax]))
        UD[i] = [em.mul(x, Dinv[i]) for x in U]
        if lam == 0:
            continue
        ud = UD[i]
        Aa, Ba, Ca = [[None] * 3 for _ in range(3)], [[None] * 3 for _ in range(3)], \
            [[None] * 3 for _ in range(3)]
        for r in range(3):
            for k in range(3):
                Ba[r][k] = em.add((1, Bm[r][k]), (-1, em.mul(ud[r], U[3 + k])))
                if k >= r:
                    Aa[r][k] = Aa[k][r] = em.add((1, A[r][k]), (-1, em.mul(ud[r], U[k])))
                    Ca[r][k] = Ca[k][r] = em.add((1, C[r][k]), (-1, em.mul(ud[3 + r], U[3 + k])))
        cl, ca = c[i]
        fl, nn = pA[i]
        pa_l = [em.add((1, fl[r]), (1, em.dot(Aa[r], cl)), (1, em.dot(Ba[r], ca)),
                       (1, em.mul(ud[r], u[i]))) for r in range(3)]
        pa_a = [em.add((1, nn[r]), (1, em.dot([Ba[0][r], Ba[1][r], Ba[2][r]], cl)),
                       (1, em.dot(Ca[r], ca)), (1, em.mul(ud[3 + r], u[i]))) for r in range(3)]
        # to the parent frame: rotate, then translate by p (the placement's origin)
        R, p = Rs[j], ps[j]
        A1, B1, C1 = _rotate(em, R, Aa, True), _rotate(em, R, Ba, False), _rotate(em, R, Ca, True)
        Ap = [em.cross(A1[r], p) for r in range(3)]  # rows of A1 [p]x
        Bl = [[em.add((1, B1[r][k]), (-1, Ap[r][k])) for k in range(3)] for r in range(3)]
        pB = [em.cross(p, [Bl[0][k], Bl[1][k], Bl[2][k]]) for k in range(3)]  # cols of [p]x Bl
        Bp = [em.cross([B1[0][r], B1[1][r], B1[2][r]], p) for r in range(3)]  # rows of B1^T [p]x
        Cl = [[None] * 3 for _ in range(3)]
        for r in range(3):
            for k in range(r, 3):
                Cl[r][k] = Cl[k][r] = em.add((1, C1[r][k]), (1, pB[k][r]), (-1, Bp[r][k]))
        A0, B0, C0 = IA[lam]
        IA[lam] = tuple([[em.add((1, X0[r][k]), (1, X1[r][k])) for k in range(3)]
                         for r in range(3)] for X0, X1 in ((A0, A1), (B0, Bl), (C0, Cl)))
        fp = em.matvec(R, pa_l)
        np_ = em.vadd(em.matvec(R, pa_a), em.cross(p, fp))
        pA[lam] = [em.vadd(pA[lam][0], fp), em.vadd(pA[lam][1], np_)]
    a = {0: ([em._neg(x) for x in g], zero)}
    qdd = [None] * n
    for j in range(n):  # pass 3: accelerations
        i, lam = j + 1, parents[j]
        R, p = Rs[j], ps[j]
        al, bl = a[lam]
        b_i = em.vadd(em.matTvec(R, bl), c[i][1])
        a_i = em.vadd(em.matTvec(R, em.vsub(al, em.cross(p, bl))), c[i][0])
        qdd[j] = em.add((1, em.mul(Dinv[i], u[i])),
                        *[(-1, em.mul(x, y)) for x, y in zip(UD[i], a_i + b_i, strict=True)])
        e = ["0", "0", "0"]
        e[axes[j]] = qdd[j]
        a[i] = (a_i, em.vadd(b_i, e))
    return qdd


_PROLOGUE = """\
static inline void {name}_sincos(int B, const double * __restrict q, double * __restrict s,
                                 double * __restrict c)
{{
  rrr_dyn_sincos({n} * B, q, s, c);
}}
"""


_ARGS = {
    "crba": "const double * __restrict q, double * __restrict out",
    "nle": "const double * __restrict q, const double * __restrict v, double * __restrict out",
    "gravity": "const double * __restrict q, double * __restrict out",
    "fd": "const double * __restrict q, const double * __restrict v, const double * "
          "__restrict tau, double * __restrict out",
    "id": "const double * __restrict q, const double * __restrict v, const double * "
          "__restrict a, double * __restrict out",
}

#: The forward-dynamics algorithms the generator writes: CRBA + RNEA + unrolled L D L^T, and
#: the articulated-body algorithm.
FD_ALGORITHMS = ("ldlt", "aba")

_TOKEN = re.compile(r"\b[th]\d+\b")
_INPUT = re.compile(r"P\(\d+\)|\bh\d+\b")


def _build(axes, parents, hoist):
    """Emit every function of one structure: ``{function: (emitter, [(index, expression)])}``."""
    n = len(axes)
    out = {}
    em = _Emitter(hoist)
    M = _crba(em, axes, parents)
    out["crba"] = em, [(r * n + k, M[r][k]) for r in range(n) for k in range(n)]
    em = _Emitter(hoist)
    out["nle"] = em, list(enumerate(_rnea(em, axes, parents, True)))
    em = _Emitter(hoist)
    out["gravity"] = em, list(enumerate(_rnea(em, axes, parents, False)))
    em = _Emitter(hoist)
    out["id"] = em, list(enumerate(_rnea(em, axes, parents, True, True)))
    em = _Emitter(hoist)
    M = _crba(em, axes, parents)
    nle = _rnea(em, axes, parents, True)
    out["ldlt"] = em, list(enumerate(_ldlt_solve(
        em, M, [em.add((1, f"T({j})"), (-1, nle[j])) for j in range(n)])))
    em = _Emitter(hoist)
    out["aba"] = em, list(enumerate(_aba(em, axes, parents)))
    return out


def _live(temps: dict, roots) -> set:
    """Names (``t<k>``/``h<k>``) the expressions ``roots`` need, transitively, in ``temps``."""
    live, todo = set(), [t for r in roots for t in _TOKEN.findall(r)]
    while todo:
        t = todo.pop()
        if t not in live and t in temps:
            live.add(t)
            todo += _TOKEN.findall(temps[t])
    return live


def _count(exprs) -> dict:
    """Operations of expressions: ``add`` (+ and binary -), ``mul``, ``div``, ``neg`` (unary)."""
    c = {"add": 0, "mul": 0, "div": 0, "neg": 0}
    for e in exprs:
        binary = [e.count(op) for op in _BINARY]
        c["add"] += binary[0] + binary[1]
        c["mul"] += binary[2]
        c["div"] += binary[3]
        c["neg"] += e.count("-") - binary[1]
    return c


def _structure_of(model):
    n = model.nq
    kinds = [model.joints[i].shortname() for i in range(1, model.njoints)]
    bad = [k for k in kinds if k not in JOINT_AXES]
    if bad or model.nq != model.nv or len(kinds) != n:
        raise ValueError(f"cannot generate dynamics for joints {bad or kinds}: only revolute "
                         f"joints about x, y or z ({', '.join(JOINT_AXES)})")
    return [JOINT_AXES[k] for k in kinds], [int(model.parents[i]) for i in range(1, model.njoints)]


def operation_counts(model, *, hoisted: bool = True) -> dict:
    """Arithmetic of each generated function of ``model``'s structure, per plant and call.

    Counts the operations of the expressions the outputs need (what the emitted C computes;
    exact zeros and ones are folded away, identical expressions named once):
    ``{"crba" | "nle" | "gravity" | "id" | "ldlt" | "aba" | "pre": {"add", "mul", "div", "neg",
    "sincos", "total"}}``, ``total = add + mul + div`` (unary minus, a sign flip, apart, as in
    Featherstone's counts), ``sincos``: the ``sin`` and ``cos`` of the joint angles (2 n).
    ``ldlt`` is the forward dynamics by CRBA + RNEA + L D L^T, ``aba`` by the articulated-body
    algorithm; ``pre`` the parameter-only expressions computed once per plant
    (``hoisted=False``: none, everything at every call, as before generator version 2).
    """
    axes, parents = _structure_of(model)
    hoist = _Hoist() if hoisted else None
    built = _build(axes, parents, hoist)
    out, used = {}, set()
    for fn, (em, outs) in built.items():
        temps = dict(em.temps)
        live = _live(temps, [e for _, e in outs])
        c = _count(temps[t] for t in live)
        c["sincos"] = 2 * len(axes)
        c["total"] = c["add"] + c["mul"] + c["div"]
        out[fn] = c
        used |= {t for t in live for t in _INPUT.findall(temps[t])}
        used |= {t for _, e in outs for t in _INPUT.findall(e)}
    hl = dict(hoist.lines) if hoist is not None else {}
    live = _live(hl, [t for t in used if t.startswith("h")])
    c = _count(hl[t] for t in live)
    c["sincos"] = 0
    c["total"] = c["add"] + c["mul"] + c["div"]
    out["pre"] = c
    return out


def fd_algorithm(counts: dict) -> str:
    """Return the forward-dynamics algorithm of fewer operations per call (ties: ``"ldlt"``)."""
    return "aba" if counts["aba"]["total"] < counts["ldlt"]["total"] else "ldlt"


def featherstone_aba_operations(n: int) -> int:
    """Featherstone's operation count of the articulated-body algorithm, ``n`` revolute joints.

    ``(224 n - 174)`` multiplications plus ``(205 n - 173)`` additions: R. Featherstone, *Rigid
    Body Dynamics Algorithms*, Springer 2008, ch. 10 (the cost table of the ABA for a chain of
    revolute joints, transforms and joint axes in their efficient form).
    """
    return (224 * n - 174) + (205 * n - 173)


def _function(name: str, fn: str, args: str, em: _Emitter, outs, index: dict, n: int) -> str:
    """One batched function: its live expressions, hoisted inputs read from ``D``."""
    temps = dict(em.temps)
    live = _live(temps, [e for _, e in outs])

    def rd(expr):
        return _INPUT.sub(lambda m: f"D({index[m.group(0)]})", expr)

    lines = [f"RRR_DYN_CLONES void {name}_{fn}(int B, const double * __restrict D_, {args})",
             "{", f"  double s_[{n} * RRR_DYN_BMAX], c_[{n} * RRR_DYN_BMAX];",
             f"  {name}_sincos(B, q, s_, c_);",
             "#pragma omp simd", "  for (int b = 0; b < B; ++b)", "  {"]
    lines += [f"      const double {t} = {rd(e)};" for t, e in em.temps if t in live]
    lines += [f"      out[{k} * B + b] = {rd(e)};" for k, e in outs]
    lines += ["  }", "}", ""]
    return "\n".join(lines)


def generate(name: str, model, *, source: str, hoisted: bool = True, other: bool = True,
             only: tuple | None = None) -> str:
    """C source of the batched functions for the structure of ``model``.

    ``<name>_pre(B, P, D)`` turns parameter vectors into the derived vectors ``D`` (the
    parameter-only expressions, once per plant); ``<name>_crba``, ``_nle``, ``_gravity`` and
    ``_fd`` take ``D``. ``_fd`` is the forward-dynamics algorithm of fewer operations
    (:func:`fd_algorithm`, named by ``<name>_dyn_fd``); ``_fd_other`` is the other one (with
    ``other``).

    Parameters
    ----------
    name : str
        C identifier prefix, e.g. ``"rrr"``.
    model : pinocchio.Model
        Only its structure (:func:`structure`) is used; no number of it enters the code.
    source : str
        Where the model came from, for the header.
    hoisted : bool, default True
        False: every expression at every call, ``<name>_pre`` only copying the parameters the
        functions read (the previous generator's arithmetic; for tests and measurements). The
        forward-dynamics algorithm is the hoisted code's choice either way.
    other : bool, default True
        Also write ``<name>_fd_other``, the algorithm not chosen (the committed files, so that
        tests compare both with Pinocchio). False for the structures built at first use: it
        would add some 60-90 % to their compile time (measured, 7 joints) for no run-time use.
    only : tuple of str, optional
        Write these functions alone (of ``"crba"``, ``"nle"``, ``"gravity"``, ``"fd"``,
        ``"id"``), besides ``<name>_pre``: an exported controller needs ``crba``, ``nle`` and
        ``gravity`` (:mod:`rrr_pin.deploy.writer`), and each function left out is compile time
        saved.

    Raises
    ------
    ValueError
        A joint type the generator does not handle.
    """
    axes, parents = _structure_of(model)
    n = len(axes)
    npar = 3 + PER_JOINT * n
    st = structure(model)
    hoist = _Hoist() if hoisted else None
    built = _build(axes, parents, hoist)
    counts = operation_counts(model, hoisted=hoisted)
    chosen = fd_algorithm(operation_counts(model) if not hoisted else counts)
    order = [("crba", "crba"), ("nle", "nle"), ("gravity", "gravity"), ("fd", chosen),
             ("id", "id")]
    unchosen = "aba" if chosen == "ldlt" else "ldlt"
    if other and only is None:
        order.append(("fd_other", unchosen))
    if only is not None:
        order = [(fn, key) for fn, key in order if fn in only]
    # The derived vector D: every parameter and hoisted expression a function reads.
    index = {}
    for _, key in order:
        em, outs = built[key]
        temps = dict(em.temps)
        live = _live(temps, [e for _, e in outs])
        for text in [temps[t] for t, _ in em.temps if t in live] + [e for _, e in outs]:
            for tok in _INPUT.findall(text):
                index.setdefault(tok, len(index))
    lines = hoist.lines if hoist is not None else []
    live = _live(dict(lines), [t for t in index if t.startswith("h")])
    pre = [f"      const double {t} = {e};" for t, e in lines if t in live]
    pre += [f"      D({k}) = {tok};" for tok, k in index.items()]
    nd = len(index)
    summary = ", ".join(f"{fn} {counts[key]['total']}" for fn, key in order[:4])
    if only is not None:
        summary += f" (only {', '.join(only)} written)"
    parts = [f"""\
/* GENERATED by scripts/gen_dynamics.py (rrr_pin.sim.dyngen version {VERSION}) -- do not edit.
 * Structure-of-arrays dynamics of the structure {st}
 * (made from {source}); every number of the plant is an input: parameter vector P of
 * {npar} entries (rrr_pin.sim.dyngen.parameter_layout), x[k * B + b] = entry k of plant b.
 * {name}_pre turns P into the derived vector D ({nd} entries: the parameter-only expressions,
 * once per plant); the other functions take D. Operations per plant and call (+, -, *, /):
 * {summary} ({chosen}; {unchosen}: {counts[unchosen]['total']}); pre {counts['pre']['total']}.
 */
#include <math.h>

#include "dyn_common.h"

const char {name}_dyn_structure[] = "{st}";
const char {name}_dyn_fd[] = "{chosen}";
const int {name}_dyn_nq = {n};
const int {name}_dyn_np = {npar};
const int {name}_dyn_nd = {nd};

#define P(k) P_[(k) * B + b]
#define D(k) D_[(k) * B + b]
#define S(j) s_[(j) * B + b]
#define C(j) c_[(j) * B + b]
#define V(j) v[(j) * B + b]
#define A(j) a[(j) * B + b]
#define T(j) tau[(j) * B + b]
""", _PROLOGUE.format(name=name, n=n)]
    parts.append("\n".join([
        f"RRR_DYN_CLONES void {name}_pre(int B, const double * __restrict P_, "
        f"double * __restrict D_)", "{", "#pragma omp simd", "  for (int b = 0; b < B; ++b)",
        "  {", *pre, "  }", "}", ""]))
    for fn, key in order:
        em, outs = built[key]
        parts.append(_function(name, fn, _ARGS["fd" if fn == "fd_other" else fn], em, outs,
                               index, n))
    return "\n".join(parts)
