"""The Levenberg–Marquardt loop of a re-embedding and the continuation that drives it (see :mod:`shspec.embed.embed`)."""

from __future__ import annotations

import numpy as np

from ..core.damping import nielsen_update
from .continuation import continuation_schedule
from .lengths import target_edge_lengths

__all__ = ["lm_iterate", "run_continuation"]


def lm_iterate(system, x, lengths, pressure, max_iter, opt, history, stats):
    """Levenberg–Marquardt with the bi-Laplacian trust region of the module notes; returns x and whether ``opt.tol``
    or ``opt.strain_tol`` was met (or no further decrease is possible).  μ lives in ``system.damping`` and carries
    over between calls; ``stats`` counts CG iterations, rejected steps and factorizations."""
    floor = opt.min_damping if opt.min_damping is not None else opt.damping
    ceiling = 1e8 * floor
    growth = 2.0
    e0 = system.energy(x, lengths, pressure)
    for _ in range(max_iter):
        if system._lu is None or not 0.25 <= system.damping / system._factored_damping <= 4.0:
            system.precondition(lengths)
            stats["factorizations"] = stats.get("factorizations", 0) + 1
        A = system.matrix(x, lengths)
        J = system.jacobian(x, lengths)
        r = system.residual(x, lengths)
        if not pressure and np.sqrt(np.mean(r * r)) <= opt.strain_tol:
            return x, True
        grad = (J.T @ r).reshape(-1, 3) / r.size
        if pressure:
            grad -= pressure * system.volume_gradient(x) / (4.0 * np.pi)
        # CG from zero on an SPD matrix returns a descent direction however early it stops, so a loose
        # tolerance only costs iterations, never robustness.
        delta, its = system.solve(A, -grad, opt.cg_tol, opt.cg_maxiter)
        stats["nnz"] = A.nnz
        stats["cg"] += its
        Jd = J @ delta.ravel()
        predicted = -(float(np.vdot(grad, delta)) + 0.5 * float(Jd @ Jd) / r.size)
        if not predicted > 0:
            return x, True
        trial = x + delta
        e1 = system.energy(trial, lengths, pressure)
        gain = (e0 - e1) / predicted
        if not gain > 0:
            stats["rejected"] = stats.get("rejected", 0) + 1
            if system.damping >= ceiling:
                # No decrease even with a tiny, smooth step: the energy is at rounding level.
                return x, True
        system.damping, growth = nielsen_update(system.damping, growth, gain, floor=floor, ceiling=ceiling)
        if gain > 0:
            x = trial
            history.append(e1)
            decrease = e0 - e1
            e0 = e1
            if gain > 0.25 and decrease <= opt.tol * max(abs(e1), 1e-300):
                return x, True
    return x, False


def run_continuation(system, sphere, c, area, x, opt, history, stats):
    """Run the continuation c^t, t → 1, with pressure; returns x, the last lengths, accepted steps and retries.

    ``c`` are the factors divided by their mean (area weights ``area``), so that c^t cannot overflow.
    """
    if opt.steps is not None:
        schedule = list(continuation_schedule(c, opt.steps))
        adaptive = False
        dt = 1.0 / opt.steps
    else:
        adaptive = True
        dt = float(continuation_schedule(c, None, max_log_step=opt.max_log_step)[0])
    t, strain, steps, retries = 0.0, 0.0, 0, 0
    while t < 1.0:
        t_new = schedule[steps] if not adaptive else (1.0 if t + 1.5 * dt >= 1.0 else t + dt)
        ct = c ** t_new
        # Each intermediate metric is rescaled to area 4π: only the shape changes from step to step.
        lengths = target_edge_lengths(sphere, ct, system.edges) * np.sqrt(4.0 * np.pi / (ct @ area))
        system.precondition(lengths)
        stats["factorizations"] = stats.get("factorizations", 0) + 1
        damping, n_hist = system.damping, len(history)
        y, _ = lm_iterate(system, x, lengths, opt.pressure, opt.iterations, opt, history, stats)
        r = system.residual(y, lengths)
        new_strain = float(np.sqrt(np.mean(r * r)))
        if (adaptive and new_strain > max(opt.continuation_strain, 2.0 * strain)
                and t_new - t > opt.min_step * 1.0001):
            # Undo: the iterations did not catch up with this much change of the metric.
            del history[n_hist:]
            system.damping = damping
            dt = max(opt.min_step, 0.5 * (t_new - t))
            retries += 1
            continue
        dt = min(2.0 * (t_new - t), 1.0)
        x, t, strain = y, t_new, new_strain
        steps += 1
    return x, lengths, steps, retries
