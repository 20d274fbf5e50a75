r"""Kajita's second stage, the dynamic filter (Kajita et al., ICRA 2003, section IV):
the first stage plans the CoM with the cart-table model; the whole body does not move as
a cart on a table (the swing leg's momentum, the CoM's height kept by bent legs), so its
ZMP differs from the plan's. The filter measures that difference on the whole body and
corrects the CoM by a second preview controller.

1. **The whole-body motion of the plan**, one configuration per sample ``t_k = k T``, by
   inverse kinematics on the robot's Pinocchio model: the ankles at the generator's
   references, the CoM at ``comref``, the waist's orientation at its reference, all
   exact (:data:`ITERATIONS` Gauss-Newton steps from the previous sample's
   configuration, residual checked below :data:`TOLERANCE`), and the rest of the body
   as close as possible to half-sitting (the least-squares step in the null space of
   those rows). This is the stack the walking graph runs, without its controller.
2. **Its multibody ZMP**, from the rate of the centroidal momentum at
   ``(q_k, v_k, a_k)`` (``v_k = (q_(k+1) (-) q_k) / T``, ``a_k = (v_k - v_(k-1)) / T``):
   ``p_mb,k``, and the error ``e_k = p_mb,k - p_cart,k`` against the cart-table ZMP of
   the planned CoM ``p_cart = c - (z_c / g) ddc``.
3. **The correction**: a small CoM displacement ``dc`` moves the multibody ZMP by about
   its own cart-table ZMP ``C dX``; so a preview controller with the first stage's gains
   tracks the reference ``-e`` from rest, and its states ``dX_k`` and jerks ``du_k`` are
   added to the first stage's (:meth:`sotpy.walking.walks.FootstepWalk.setCorrection`).

``passes`` repeats 1-3 on the corrected plan (each pass corrects what the previous one
left). The filter runs when the plan is made (a ``:stepseq`` or ``addStep`` before the
trigger), never in a tick: on Talos a 15-step plan (3300 samples) takes about a second.
Steps added during the walk are not filtered.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..errors import CommandError
from .preview import PreviewController

__all__ = ["ITERATIONS", "TOLERANCE", "dynamicFilter", "multibodyZmp", "wholeBodyMotion"]

#: Gauss-Newton steps of the inverse kinematics per sample.
ITERATIONS = 3
#: The largest residual (m and rad) of the exact rows the inverse kinematics accepts.
TOLERANCE = 1e-6


def wholeBodyMotion(geometry, references, times: np.ndarray, q0: np.ndarray) -> np.ndarray:
    """The configurations (len(times) x nq) that put the ankles, the CoM and the waist's
    orientation on ``references(t) -> (com (3,), {side: SE3}, R_waist)`` at each time,
    the rest of the body nearest half-sitting (module doc, step 1), from ``q0``.

    Raises:
        CommandError: a sample whose rows cannot be met (a reference out of reach).
    """
    model = geometry.model
    data = model.createData()
    ids = geometry.ankleFrames
    waist = geometry.waistFrame
    posture = geometry.posture
    q = np.asarray(q0, dtype=float).copy()
    out = np.empty((len(times), model.nq))
    for k, t in enumerate(times):
        com, ankles, Rw = references(float(t))
        for _ in range(ITERATIONS):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            rows, errs = [], []
            for side in ("left", "right"):
                M = data.oMf[ids[side]]
                err = pin.log6(M.actInv(ankles[side])).vector  # in the ankle's frame
                J = pin.getFrameJacobian(model, data, ids[side], pin.LOCAL)
                rows.append(pin.Jlog6(M.actInv(ankles[side])) @ J)
                errs.append(err)
            c = pin.centerOfMass(model, data, q, False)
            rows.append(pin.jacobianCenterOfMass(model, data, q, False))
            errs.append(com - c)
            Mw = data.oMf[waist]
            ew = pin.log3(Mw.rotation.T @ Rw)
            Jw = pin.getFrameJacobian(model, data, waist, pin.LOCAL)[3:]
            rows.append(pin.Jlog3(Mw.rotation.T @ Rw) @ Jw)
            errs.append(ew)
            A = np.vstack(rows)
            e = np.concatenate(errs)
            if np.max(np.abs(e)) < TOLERANCE * 1e-3:
                break
            Ap = np.linalg.pinv(A, rcond=1e-10)
            rest = pin.difference(model, q, posture)
            dq = Ap @ e + rest - Ap @ (A @ rest)
            q = pin.integrate(model, q, dq)
        if np.max(np.abs(e)) > TOLERANCE:
            raise CommandError(
                f"dynamic filter: the whole body cannot follow the plan at t = {t:.3f} s "
                f"(residual {np.max(np.abs(e)):.3g} m or rad after {ITERATIONS} steps)"
            )
        out[k] = q
    return out


def multibodyZmp(model, qs: np.ndarray, period: float, gravity: float = 9.81) -> np.ndarray:
    """The multibody ZMP (len(qs) x 2, m) of the motion ``qs`` sampled every ``period``
    (s) (module doc, step 2); the first and last samples repeat their neighbours'."""
    data = model.createData()
    n = len(qs)
    v = np.zeros((n, model.nv))
    for k in range(n - 1):
        v[k] = pin.difference(model, qs[k], qs[k + 1]) / period
    v[-1] = v[-2]
    out = np.empty((n, 2))
    mg = np.array([0.0, 0.0, gravity])
    for k in range(n):
        a = (v[k] - v[k - 1]) / period if k else np.zeros(model.nv)
        pin.computeCentroidalMomentumTimeVariation(model, data, qs[k], v[k], a)
        c = data.com[0]
        f = data.dhg.linear + data.mass[0] * mg
        tau = data.dhg.angular
        out[k] = (c[0] - (tau[1] + c[2] * f[0]) / f[2], c[1] + (tau[0] - c[2] * f[1]) / f[2])
    out[0] = out[1]
    return out


def dynamicFilter(pg, walk, passes: int = 1) -> dict[str, float]:
    """Correct ``walk`` (a :class:`~sotpy.walking.walks.FootstepWalk` of the generator
    ``pg``) by the module doc's ``passes`` passes. Returns the p99 and max (m) of the
    multibody ZMP's distance to the cart-table ZMP before and after the filter, as the
    filter's own model predicts them (``before_p99``, ``before_max``, ``after_p99``,
    ``after_max``)."""
    geo = pg.geometry
    T = walk.T
    n = walk.samples
    times = np.arange(n) * T
    gains = walk.gains
    r = gains.comHeight / gains.gravity
    dS = np.zeros((n, 3, 2))
    dU = np.zeros((n, 2))
    stats: dict[str, float] = {}
    q0 = pg.initialConfiguration
    first = walk.sampleStates()
    target = first[:, 0] - r * first[:, 2]  # the first stage's cart-table ZMP
    for i in range(passes + 1):
        qs = wholeBodyMotion(geo, lambda t: pg.referencesAt(walk, t), times, q0)
        zmp = multibodyZmp(geo.model, qs, T, gains.gravity)
        err = zmp - target
        d = np.linalg.norm(err[1:-1], axis=1)
        tag = "before" if i == 0 else "after"
        stats[f"{tag}_p99"], stats[f"{tag}_max"] = float(np.percentile(d, 99)), float(d.max())
        if i == passes:
            break
        ctrl = PreviewController(gains, np.zeros((3, 2)))
        ref = np.vstack((-err, np.zeros((gains.F.size + 1, 2))))
        for k in range(n):
            dS[k] += ctrl.state
            dU[k] += ctrl.step(ref[k : k + gains.F.size + 1])
        walk.setCorrection(dS.copy(), dU.copy())
    return stats
