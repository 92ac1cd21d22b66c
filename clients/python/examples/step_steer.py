"""Step steer (ISO 7401) at three speeds, in lockstep, with the yaw-rate plot.

For each speed the car runs straight at a held speed (the speed control), then the road-wheel
angle ramps in 0.1 s to the angle that gives 4 m/s^2 of steady lateral acceleration by the linear
bicycle model; 3 s later the steady yaw rate, the time to 90 % of it and the overshoot are read.

    vdyn-server --lockstep --world flat &
    python3 step_steer.py [--domain 0] [--out step_steer.png]
"""

import numpy as np

import vdyn
from _common import connect, figure, options, result, understeer_gradient, axle_geometry, yaw_gain

AY_TARGET = 4.0  # m/s^2, ISO 7401's reference lateral acceleration


def step_steer(sim, vid, speed_kmh, settle_s=2.0, hold_s=3.0, ramp_s=0.1):
    params = sim.params(vid)
    v = speed_kmh / 3.6
    L = axle_geometry(params)[0]
    delta = AY_TARGET * (L + understeer_gradient(params) * v * v) / (v * v)
    x0, y0 = sim.world.spawn.x, sim.world.spawn.y
    sim.teleport(vid, x0, y0, yaw=0.0, speed=v)
    steps = lambda s: int(round(s / sim.step_s))  # noqa: E731
    parts = [sim.step(steps(settle_s), vdyn.make_input(cruise_kmh=speed_kmh), vehicle_id=vid)[vid]]
    ramp = steps(ramp_s) // 10
    for k in range(10):  # the ramp in ten increments
        inp = vdyn.make_input(steer=delta * (k + 1) / 10, cruise_kmh=speed_kmh)
        parts.append(sim.step(ramp, inp, vehicle_id=vid)[vid])
    parts.append(sim.step(steps(hold_s), vdyn.make_input(steer=delta, cruise_kmh=speed_kmh),
                          vehicle_id=vid)[vid])
    t = np.concatenate([p.t for p in parts])
    r = np.concatenate([p.yaw_rate for p in parts])
    steer = np.concatenate([p["steer_in_rad"] for p in parts])
    ay = np.concatenate([p.ay_mps2 for p in parts])
    t0 = t[np.argmax(steer >= 0.5 * delta)]  # ISO 7401: time from 50 % of the steering input
    t = t - t0
    r_ss = float(np.mean(r[t > hold_s - 1.0]))
    t90 = float(t[np.argmax(r >= 0.9 * r_ss)])
    overshoot = float((np.max(r) - r_ss) / r_ss)
    return {"speed_kmh": speed_kmh, "delta_rad": delta, "r_ss": r_ss,
            "ay_ss": float(np.mean(ay[t > hold_s - 1.0])), "t90_s": t90, "overshoot": overshoot,
            "gain": r_ss / delta, "gain_linear": yaw_gain(params, v)}, (t, r)


def main():
    args = options(__doc__.splitlines()[0], "step_steer.png").parse_args()
    sim = connect(args)
    plt = figure()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    runs = []
    for kmh in (60, 80, 100):
        info, (t, r) = step_steer(sim, args.vehicle_id, kmh)
        runs.append(info)
        ax.plot(t, np.degrees(r), label=f"{kmh} km/h: r_ss {np.degrees(info['r_ss']):.2f} deg/s, "
                                        f"T90 {info['t90_s'] * 1e3:.0f} ms")
        print(f"{kmh:3d} km/h: steer {np.degrees(info['delta_rad']):.2f} deg, yaw rate "
              f"{np.degrees(info['r_ss']):.2f} deg/s, ay {info['ay_ss']:.2f} m/s^2, T90 "
              f"{info['t90_s'] * 1e3:.0f} ms, overshoot {100 * info['overshoot']:.1f} %, gain "
              f"{info['gain']:.3f} 1/s (linear bicycle {info['gain_linear']:.3f})")
    ax.set_xlim(-0.5, 3.0)
    ax.set_xlabel("time from 50 % steer, s")
    ax.set_ylabel("yaw rate, deg/s")
    ax.set_title(f"Step steer (ISO 7401) to {AY_TARGET:g} m/s^2 - {sim.world_name}, "
                 f"vehicle {args.vehicle_id}")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"figure: {args.out}")
    result(runs=runs)


if __name__ == "__main__":
    main()
