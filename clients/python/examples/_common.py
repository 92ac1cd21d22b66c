"""What the examples share: options, the bicycle model's closed forms, figures."""

import argparse
import json

import vdyn


def options(description, figure):
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--domain", type=int, default=0, help="DDS domain of the server (default 0)")
    ap.add_argument("--server-id", default=None, help="the server to use (default: the first)")
    ap.add_argument("--vehicle-id", type=int, default=1)
    ap.add_argument("--out", default=figure, help=f"the figure (default {figure})")
    ap.add_argument("--timeout", type=float, default=30.0, help="every wait, s")
    return ap


def connect(args):
    return vdyn.Client(domain=args.domain, server_id=args.server_id, timeout=args.timeout)


def axle_geometry(params):
    """Wheelbase L, CG to front axle a, CG to rear axle b (m), mass (kg), and the axles'
    cornering stiffness Cf, Cr (N/rad, two tires each) from a vehicle's parameters."""
    a, b = params.b, params.c
    cf = params.lf.cornering_stiffness + params.rf.cornering_stiffness
    cr = params.lr.cornering_stiffness + params.rr.cornering_stiffness
    return a + b, a, b, params.mass, cf, cr


def understeer_gradient(params):
    """The linear bicycle model's understeer gradient K = (m / L) (b / Cf - a / Cr), rad/(m/s^2)
    (docs/model.md; delta = L / R + K ay)."""
    L, a, b, m, cf, cr = axle_geometry(params)
    return (m / L) * (b / cf - a / cr)


def yaw_gain(params, speed):
    """Steady-state yaw-rate gain r / delta = V / (L + K V^2), 1/s."""
    L = axle_geometry(params)[0]
    return speed / (L + understeer_gradient(params) * speed * speed)


def result(**values):
    """The line a test reads: RESULT {json}."""
    print("RESULT " + json.dumps(values), flush=True)


def figure():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt
