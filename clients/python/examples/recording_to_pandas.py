"""A recording read into pandas and plotted: speed, yaw rate and the driver's input over time,
with what the recording holds (channels, vehicles, gaps, events).

    vdyn-recorder record run.mcap &   # ... a session ...
    python3 recording_to_pandas.py run.mcap [--vehicle-id 1] [--out recording.png]
"""

import argparse
import collections

import vdyn
from _common import figure, result


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording")
    ap.add_argument("--vehicle-id", type=int, default=None, help="default: the only vehicle")
    ap.add_argument("--out", default="recording.png")
    args = ap.parse_args()
    rec = vdyn.Recording(args.recording)
    print(rec)
    for c in rec.channels:
        print(f"  {c['topic']:<28} {c['messages']:8d} messages")
    for v in rec.vehicles:
        print(f"  vehicle {v['vehicle_id']}: {v['states']} states, steps {v['first_step']}.."
              f"{v['last_step']}, missing {v['missing']}")
    kinds = collections.Counter(e.WhichOneof("event") for _, e in rec.events())
    print("  events: " + ", ".join(f"{k} {n}" for k, n in sorted(kinds.items())))
    df = rec.dataframe(args.vehicle_id)
    df["t_rec_s"] = (df["log_time_ns"] - df["log_time_ns"].iloc[0]) * 1e-9
    print(df[["t_s", "speed_kmh", "wz_radps", "steer_in_rad", "throttle_in"]].describe())

    plt = figure()
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    df.plot(x="t_s", y="speed_kmh", ax=axes[0], legend=False)
    axes[0].set_ylabel("speed, km/h")
    df.plot(x="t_s", y="wz_radps", ax=axes[1], legend=False)
    axes[1].set_ylabel("yaw rate, rad/s")
    df.plot(x="t_s", y=["steer_in_rad", "throttle_in"], ax=axes[2])
    axes[2].set_ylabel("driver input")
    axes[2].set_xlabel("simulation time, s")
    for a in axes:
        a.grid(True, alpha=0.3)
    vid = args.vehicle_id if args.vehicle_id is not None else rec.vehicle_ids[0]
    axes[0].set_title(f"{args.recording.split('/')[-1]}: vehicle {vid}, {len(df)} states")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"figure: {args.out}")
    result(rows=len(df), columns=len(df.columns), events=sum(kinds.values()),
           missing=sum(rec.gaps.values()))


if __name__ == "__main__":
    main()
