"""``shspec identifiability``: before any fit, how many eigenvalues determine a ρ of degree La, and how well."""

from __future__ import annotations

import json

import numpy as np

from .help_format import HelpFormatter
from ..errors import InvalidArgumentError
from ..galerkin.truncation import basis_degree_for
from ..fitting.numeig_plan import candidate_numeigs, plan_numeig
from ..sphere.random import random_centred_coefficients
from ..fitting.targets import blob_factor, parse_target


def register(subparsers) -> None:
    """Add ``identifiability`` to the shspec command line."""
    p = subparsers.add_parser(
        "identifiability", help="how well K eigenvalues determine rho of degree La (before any fit)",
        formatter_class=HelpFormatter,
        description="For a reference rho (the built-in blob, a random smooth rho, or the harmonic truth of a mesh "
        "target), the singular values of the relative Jacobian d(lambda_i)/lambda_i over the free coefficients "
        "(gauge a_1m = 0; the three rotations counted out) for several K: rank, condition number and noise gain "
        "(relative error of rho per unit relative noise on the eigenvalues). Recommends the smallest K listed "
        "whose noise gain times --noise is below --accuracy.")
    p.add_argument("--lmax-factor", type=int, required=True, help="degree La of rho")
    p.add_argument("--numeig", default=None,
                   help="K values, comma-separated (default: (La+2)^2 and 1.25, 1.5, ..., 4 times (La+1)^2)")
    p.add_argument("--lmax", type=int, default=None,
                   help="basis band limit Lb of the analysis (default: (Lb+1)^2 >= 1.5 K for the largest K); the "
                   "recommended K gets its own Lb, the smallest at which its eigenvalues change by at most 1e-6 "
                   "from Lb - 2")
    p.add_argument("--target", default="blob",
                   help="reference rho: blob | random:SEED | star:l,m,p | mesh:PATH (the harmonic truth)")
    p.add_argument("--noise", type=float, default=1e-8, help="relative noise sigma on the eigenvalues")
    p.add_argument("--accuracy", type=float, default=1e-6, help="wanted relative L2 accuracy of rho")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(func=_identifiability)


def _ks(text, la: int) -> list[int] | None:
    if text is None:
        return None
    try:
        ks = sorted({int(v) for v in text.split(",")})
    except ValueError:
        raise InvalidArgumentError(f"--numeig takes comma-separated integers, got {text!r}") from None
    if ks[0] < 2:
        raise InvalidArgumentError(f"every K must be >= 2, got {ks[0]}")
    return ks


def _reference(text: str, la: int, lb: int) -> np.ndarray:
    if text.startswith("random:"):
        try:
            seed = int(text.split(":", 1)[1])
        except ValueError:
            raise InvalidArgumentError(f"a random reference is random:SEED, got {text!r}") from None
        return random_centred_coefficients(seed, la, 0.2)
    if text == "blob":
        return blob_factor(max(la, 6)).truncated(la).coefficients
    if text.partition(":")[0] not in ("star", "mesh"):
        # parse_target would also take (and its message offer) spectrum:FILE, which has no rho to analyse
        raise InvalidArgumentError(f"unknown reference {text!r}: use blob, random:SEED, star:l,m,p or mesh:PATH "
                                   "(identifiability analyses a known rho; a spectrum file has none)")
    target = parse_target(text, lmax=lb, numeig=2, lmax_factor=la)
    if target.truth is None:
        raise InvalidArgumentError(f"{text} has no known rho; use blob, random:SEED, star:... or mesh:...")
    return target.truth.coefficients


def _identifiability(args) -> int:
    la = args.lmax_factor
    ks = _ks(args.numeig, la)
    lb_ref = args.lmax if args.lmax is not None else basis_degree_for(max(ks or candidate_numeigs(la)), la)
    plan = plan_numeig(la, _reference(args.target, la, lb_ref), candidates=ks, noise=args.noise,
                       accuracy=args.accuracy, lmax=args.lmax)
    rows = [{k: v for k, v in r.to_dict().items() if k != "singular_values"} for r in plan.rows]
    if args.json:
        print(json.dumps({"lmax": lb_ref, "lmax_factor": la, "target": args.target, "noise": plan.noise,
                          "accuracy": plan.accuracy, "rows": rows, "recommended_numeig": plan.numeig,
                          "recommended_lmax": plan.lmax if plan.numeig is not None else None}))
        return 0
    print(f"rho: {args.target}, La = {la} ({rows[0]['free']} free coefficients, {rows[0]['symmetries']} rotations "
          f"counted out), basis Lb = {lb_ref}")
    print(f"{'K':>6} {'rank':>6} {'condition':>11} {'noise gain':>11}  determined")
    for r in rows:
        cond = "inf" if r["condition"] is None else f"{r['condition']:.3g}"
        print(f"{r['numeig']:>6} {r['rank']:>6} {cond:>11} {r['noise_gain']:>11.3g}  "
              f"{'no' if r['underdetermined'] else 'yes'}")
    if plan.numeig is None:
        print(f"no K listed reaches a relative accuracy {plan.accuracy:g} with noise {plan.noise:g}; try larger K")
    else:
        gain = next(r["noise_gain"] for r in rows if r["numeig"] == plan.numeig)
        print(f"recommended: K = {plan.numeig} with basis Lb = {plan.lmax} (noise gain x noise = "
              f"{gain * plan.noise:.2g} <= {plan.accuracy:g})")
    return 0
