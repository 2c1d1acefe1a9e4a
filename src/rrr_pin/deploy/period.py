r"""``ctrl_step_dt``: the exported law over a period it is given, K discretized at it.

The text appended to ``controller.c`` (:func:`controller_step_dt_c`) and what it does with its
period (:func:`step_dt_text`, ``CTRL_STEP_DT`` of ``controller.h``). ``K``'s continuous
realization travels in the C, and each call discretizes it at ``dt`` by the export's method when
it is a generalized bilinear transform (:data:`GBT_ALPHA`), as scipy's ``cont2discrete`` does
for python-control's ``sample_system``; at the nominal period it is ``ctrl_step`` itself.
"""

from __future__ import annotations

import numpy as np

from .sources import _matrix, _num

__all__ = ["controller_step_dt_c", "step_dt_text", "GBT_ALPHA"]

#: ``method`` of :func:`control.sample_system` -> ``alpha`` of the generalized bilinear transform
#: (scipy's ``cont2discrete``, which python-control calls): the methods ``ctrl_step_dt`` can
#: apply at each period with a linear solve. ``zoh`` and the others need a matrix exponential,
#: which the exported C does not carry.
GBT_ALPHA = {"tustin": 0.5, "bilinear": 0.5, "euler": 0.0, "forward_diff": 0.0,
             "backward_diff": 1.0}

_DT_HEAD = """
int ctrl_step_dt(ctrl_state *s, const double q[CTRL_NQ], const double qd[CTRL_NQ],
                 const double r[CTRL_NQ], const double rd[CTRL_NQ], const double rdd[CTRL_NQ],
                 double tau[CTRL_NQ], double dt)
{
"""

#: LU with partial pivoting (as LAPACK's getrf/getrs, which scipy.linalg.solve calls), on an
#: n x n row-major matrix; hand-written: no C library is assumed on the target.
_LU = """
static int lu_factor(int n, double *a, int *piv)
{
    int i, j, k;
    for (k = 0; k < n; ++k) {
        int p = k;
        double big = fabs(a[k * n + k]);
        for (i = k + 1; i < n; ++i) {
            if (fabs(a[i * n + k]) > big) {
                big = fabs(a[i * n + k]);
                p = i;
            }
        }
        piv[k] = p;
        if (!(big > 0.0)) {
            return 0;
        }
        if (p != k) {
            for (j = 0; j < n; ++j) {
                double t = a[k * n + j];
                a[k * n + j] = a[p * n + j];
                a[p * n + j] = t;
            }
        }
        for (i = k + 1; i < n; ++i) {
            a[i * n + k] /= a[k * n + k];
            for (j = k + 1; j < n; ++j) {
                a[i * n + j] -= a[i * n + k] * a[k * n + j];
            }
        }
    }
    return 1;
}

static void lu_solve(int n, const double *a, const int *piv, double *b)
{
    int i, j;
    for (i = 0; i < n; ++i) {
        if (piv[i] != i) {
            double t = b[i];
            b[i] = b[piv[i]];
            b[piv[i]] = t;
        }
    }
    for (i = 0; i < n; ++i) {
        for (j = 0; j < i; ++j) {
            b[i] -= a[i * n + j] * b[j];
        }
    }
    for (i = n - 1; i >= 0; --i) {
        for (j = i + 1; j < n; ++j) {
            b[i] -= a[i * n + j] * b[j];
        }
        b[i] /= a[i * n + i];
    }
}
"""


def step_dt_text(form, continuous=None, *, method: str | None = None,
                 prewarp: float | None = None) -> str:
    """Return what ``ctrl_step_dt`` does with its period (``CTRL_STEP_DT`` of controller.h).

    ``method`` None with no ``continuous``: a discrete ``K`` exported as given.
    """
    if form.kind == "pd" or not form.A.shape[0]:
        return "period-free: the law holds no discrete-time state; dt is checked, not used"
    if continuous is None:
        why = ("K is discrete as given" if method is None else
               f"method {method!r} is not one the C discretizes per period ("
               + ", ".join(GBT_ALPHA) + ")")
        return f"nominal period only: {why}; dt other than CTRL_PERIOD is CTRL_EPERIOD"
    warp = f", prewarped at {prewarp!r} rad/s" if prewarp is not None else ""
    return (f"K discretized at dt by {method} (generalized bilinear, alpha = "
            f"{GBT_ALPHA[method]!r}{warp}) from its continuous realization")


def controller_step_dt_c(form, continuous=None, *, method: str | None = None,
                         prewarp: float | None = None) -> str:
    r"""Return the text of ``ctrl_step_dt`` (appended to ``controller.c``).

    ``continuous`` is K's continuous ``(A, B, C, D)`` (shapes (m, m), (m, n), (n, m), (n, n))
    when ``method`` is one of :data:`GBT_ALPHA`: then each period ``dt`` gets scipy's
    ``cont2discrete`` generalized bilinear transform (python-control's ``sample_system``,
    with its Tustin prewarp ``T = 2 tan(w dt / 2) / w``)

    .. math:: A_d = (I - \alpha T A)^{-1} (I + (1 - \alpha) T A), \quad
              B_d = (I - \alpha T A)^{-1} T B, \quad C_d = C (I - \alpha T A)^{-1}, \quad
              D_d = D + \alpha C B_d

    (and, with anti-windup, ``L = B_d D_d^{-1}``); ``dt == CTRL_PERIOD`` runs ``ctrl_step``
    on the tables python-control computed at export. Without ``continuous``, a law with ``K``
    runs at ``CTRL_PERIOD`` only; a law without ``K`` ignores ``dt`` (after checking it).
    """
    check = "    if (!(isfinite(dt) && dt > 0.0)) {\n        return CTRL_EPERIOD;\n    }\n"
    nominal = ("    if (dt == CTRL_PERIOD) {\n        return ctrl_step(s, q, qd, r, rd, rdd, "
               "tau);\n    }\n")
    m = 0 if form.kind == "pd" else form.A.shape[0]
    if not m:
        return (f"\n/* {step_dt_text(form)}. */" + _DT_HEAD + check
                + "    return ctrl_step(s, q, qd, r, rd, rdd, tau);\n}\n")
    if continuous is None:
        return (f"\n/* {step_dt_text(form, method=method)}. */" + _DT_HEAD + check + nominal
                + "    return CTRL_EPERIOD;\n}\n")
    A, B, C, D = (np.asarray(M, dtype=float) for M in continuous)
    alpha = GBT_ALPHA[method]
    aw = form.kind == "fl_aw"
    tables = (_matrix("CT_A", A) + _matrix("CT_B", B) + _matrix("CT_C", C) + _matrix("CT_D", D)
              + f"#define DT_ALPHA {_num(alpha)}\n")
    if prewarp is not None:
        tables += f"#define DT_PREWARP {_num(prewarp)} /* [rad/s] */\n"
        T = "    T = 2.0 * tan(DT_PREWARP * dt / 2.0) / DT_PREWARP;\n"
    else:
        T = "    T = dt;\n"
    gain = f"""    /* L = Bd Dd^-1: row i of L solves Dd^T z = Bd[i, :] */
    for (i = 0; i < CTRL_NQ; ++i) {{
        for (j = 0; j < CTRL_NQ; ++j) {{
            ddt[j * CTRL_NQ + i] = Dd[i][j];
        }}
    }}
    if (!lu_factor(CTRL_NQ, ddt, pivn)) {{
        return CTRL_EPERIOD;
    }}
    for (i = 0; i < {m}; ++i) {{
        for (j = 0; j < CTRL_NQ; ++j) {{
            z[j] = Bd[i][j];
        }}
        lu_solve(CTRL_NQ, ddt, pivn, z);
        for (j = 0; j < CTRL_NQ; ++j) {{
            Ld[i][j] = z[j];
        }}
    }}
""" if aw else ""
    decl = (f"    double Ad[{m}][{m}], Bd[{m}][CTRL_NQ], Cd[CTRL_NQ][{m}], "
            f"Dd[CTRL_NQ][CTRL_NQ];\n"
            f"    double ima[{m} * {m}], imt[{m} * {m}], z[{m} > CTRL_NQ ? {m} : CTRL_NQ];\n"
            f"    int piv[{m}], pivt[{m}];\n")
    if aw:
        decl += f"    double Ld[{m}][CTRL_NQ], ddt[CTRL_NQ * CTRL_NQ];\n    int pivn[CTRL_NQ];\n"
    decl += "    double T;\n    int i, j, k;\n"
    what = step_dt_text(form, continuous, method=method, prewarp=prewarp)
    return f"\n/* {what}. */\n" + tables + _LU + _DT_HEAD + decl + check + nominal + T + (
        f"""    /* ima = I - alpha T A, and its transpose (factored apart, as scipy solves each) */
    for (i = 0; i < {m}; ++i) {{
        for (j = 0; j < {m}; ++j) {{
            ima[i * {m} + j] = (i == j ? 1.0 : 0.0) - DT_ALPHA * T * CT_A[i][j];
            imt[j * {m} + i] = ima[i * {m} + j];
        }}
    }}
    if (!lu_factor({m}, ima, piv) || !lu_factor({m}, imt, pivt)) {{
        return CTRL_EPERIOD;
    }}
    /* Ad = ima^-1 (I + (1 - alpha) T A), Bd = ima^-1 T B, column by column */
    for (j = 0; j < {m}; ++j) {{
        for (i = 0; i < {m}; ++i) {{
            z[i] = (i == j ? 1.0 : 0.0) + (1.0 - DT_ALPHA) * T * CT_A[i][j];
        }}
        lu_solve({m}, ima, piv, z);
        for (i = 0; i < {m}; ++i) {{
            Ad[i][j] = z[i];
        }}
    }}
    for (j = 0; j < CTRL_NQ; ++j) {{
        for (i = 0; i < {m}; ++i) {{
            z[i] = T * CT_B[i][j];
        }}
        lu_solve({m}, ima, piv, z);
        for (i = 0; i < {m}; ++i) {{
            Bd[i][j] = z[i];
        }}
    }}
    /* Cd = C ima^-1: row i of Cd solves ima^T z = C[i, :]; Dd = D + alpha C Bd */
    for (i = 0; i < CTRL_NQ; ++i) {{
        for (k = 0; k < {m}; ++k) {{
            z[k] = CT_C[i][k];
        }}
        lu_solve({m}, imt, pivt, z);
        for (k = 0; k < {m}; ++k) {{
            Cd[i][k] = z[k];
        }}
        for (j = 0; j < CTRL_NQ; ++j) {{
            double cb = 0.0;
            for (k = 0; k < {m}; ++k) {{
                cb += CT_C[i][k] * Bd[k][j];
            }}
            Dd[i][j] = CT_D[i][j] + DT_ALPHA * cb;
        }}
    }}
{gain}    return law_step(s, q, qd, r, rd, rdd, tau, (const double (*)[{m}])Ad,
                    (const double (*)[CTRL_NQ])Bd, (const double (*)[{m}])Cd,
                    (const double (*)[CTRL_NQ])Dd{", (const double (*)[CTRL_NQ])Ld" if aw else ""});
}}
""")
