"""The examples run against real servers and write their figures; their numbers are checked
against closed forms. Also: pip installs the package into a venv, where it imports."""

import json
import os
import runpy
import subprocess
import sys

import pytest

from conftest import SERVER

EXAMPLES = os.path.join(os.environ.get("VDYN_PYTHON_SOURCE", ""), "examples")


def run_example(name, args, tmp_path, capsys):
    """Runs an example as its command line does, in this interpreter (matplotlib and the
    package loaded once for all examples)."""
    fig = tmp_path / (name + ".png")
    argv, path = sys.argv, sys.path[:]
    sys.argv = [name + ".py", *args, "--out", str(fig)]
    sys.path.insert(0, EXAMPLES)
    try:
        runpy.run_path(os.path.join(EXAMPLES, name + ".py"), run_name="__main__")
    finally:
        sys.argv, sys.path[:] = argv, path
    out = capsys.readouterr().out
    assert fig.stat().st_size > 10_000, "the figure is missing or empty"
    line = [ln for ln in out.splitlines() if ln.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


@pytest.fixture
def flat_server(start, domain):
    def run(*extra):
        start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--world", "flat",
               "--domain", str(domain), *extra], "server")
    return run


def test_step_steer_at_three_speeds(flat_server, domain, tmp_path, capsys):
    flat_server()
    r = run_example("step_steer", ["--domain", str(domain)], tmp_path, capsys)["runs"]
    assert [x["speed_kmh"] for x in r] == [60, 80, 100]
    for x in r:
        # Steady state reached near ISO 7401's 4 m/s^2, a yaw rate settled within 0.5 s.
        assert 3.0 < x["ay_ss"] < 4.5
        assert 0.05 < x["t90_s"] < 0.5
        # Near the linear bicycle model's gain (the full model: load transfer, steering system).
        assert x["gain"] == pytest.approx(x["gain_linear"], rel=0.15)
    # An understeering car below its characteristic speed: the gain grows with speed.
    assert r[0]["gain"] < r[1]["gain"] < r[2]["gain"]


def test_steady_circle_understeer_gradient_matches_the_closed_form(flat_server, domain, tmp_path, capsys):
    flat_server("--model", "paper")
    r = run_example("steady_circle", ["--domain", str(domain)], tmp_path, capsys)
    assert r["K_closed"] > 0
    assert r["K_measured"] == pytest.approx(r["K_closed"], rel=0.03)


def test_mass_sweep_follows_the_closed_form(flat_server, domain, tmp_path, capsys):
    flat_server("--model", "paper")
    r = run_example("mass_sweep", ["--domain", str(domain), "--masses", "1000,1600,2200"],
                    tmp_path, capsys)
    assert r["masses"] == [1000.0, 1600.0, 2200.0]
    for measured, closed in zip(r["measured"], r["closed"]):
        assert measured == pytest.approx(closed, rel=0.01)
    assert r["measured"][0] > r["measured"][1] > r["measured"][2]


def test_a_recording_into_pandas_and_plotted(recorded_run, tmp_path, capsys):
    out, got = recorded_run
    r = run_example("recording_to_pandas", [str(out)], tmp_path, capsys)
    assert r["rows"] == sum(len(s) for s in got) == 2000  # a lockstep server: only stepped states
    assert r["missing"] == 0 and r["events"] > 0


def test_pip_installs_the_package_into_a_venv(tmp_path):
    import vdyn
    package_dir = os.path.dirname(os.path.dirname(vdyn.__file__))
    venv = tmp_path / "venv"
    # Debian's pip (python3-pip) from the system site packages: no copy of pip into the venv.
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip",
                    str(venv)], check=True, timeout=120)
    pip = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install",
                          "--no-build-isolation", "--no-index", "--no-deps", "--no-compile",
                          package_dir],
                         capture_output=True, text=True, timeout=180)
    assert pip.returncode == 0, pip.stdout + pip.stderr
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    probe = subprocess.run(
        [str(venv / "bin" / "python"), "-c",
         "import vdyn; print(vdyn.__file__); print(len(vdyn.COLUMNS)); "
         "print(vdyn.pb.VehicleParams(mass=1.0).mass)"],
        capture_output=True, text=True, timeout=60, cwd=str(tmp_path), env=env)
    assert probe.returncode == 0, probe.stderr
    where, columns, mass = probe.stdout.split()
    assert where.startswith(str(venv)), where
    assert int(columns) == len(vdyn.COLUMNS) and float(mass) == 1.0


def test_tire_curves_of_the_synthetic_file(tmp_path, capsys):
    tire = os.path.join(EXAMPLES, "..", "..", "..", "tires", "vdyn_synthetic_205_55R16_mf61.tir")
    r = run_example("tire_curves", [tire, "--server", SERVER], tmp_path, capsys)
    assert r["loads"] == [2250.0, 4500.0, 6750.0]
    nominal = r["curves"][1]
    # The file's own numbers at FNOMIN (tires/README.md, docs/model.md 8.2b): Kya = PKY1 Fz0
    # sin(PKY4 atan(1 / PKY2)) = -72.8 kN/rad; mu_y about PDY1 = 1.05 (with the shifts), mu_x
    # about PDX1 = 1.2; the aligning moment peaks before the side force, at a few degrees.
    assert nominal["Kya_N_per_rad"] == pytest.approx(-72809.0, rel=0.01)
    assert nominal["mu_y"] == pytest.approx(1.05, rel=0.02)
    assert nominal["mu_x"] == pytest.approx(1.2, rel=0.02)
    assert 1.0 < nominal["Mz_peak_alpha_deg"] < 6.0
    # Load sensitivity: the friction coefficient falls with the load (PDY2 < 0, PDX2 < 0).
    mu_y = [c["mu_y"] for c in r["curves"]]
    assert mu_y[0] > mu_y[1] > mu_y[2]


def test_a_magic_formula_tyres_inputs_and_outputs_are_columns(flat_server, domain):
    """Every tyre input and output, per wheel, every step (docs/formats.md): what a reader needs to
    evaluate the law again."""
    tire = os.path.join(EXAMPLES, "..", "..", "..", "tires", "vdyn_synthetic_205_55R16_mf61.tir")
    flat_server("--tire", tire)
    import vdyn
    import numpy as np
    sim = vdyn.Client(domain=domain, timeout=30)
    s = sim.step(2000, vdyn.make_input(steer=0.05, throttle=0.5, vehicle_id=1))[1]
    assert np.all(s.wheel("pressure_Pa") == 230000.0)  # the file's INFLPRES on every wheel
    for name in ("kappaLaw", "alphaLaw_rad", "camber_rad", "Mx_Nm", "My_Nm"):
        assert s.wheel(name).shape == (2000, 4)
    # Turning left, the body rolls right side down: every wheel leans its top to the right.
    assert np.all(s.wheel("camber_rad")[-1] > 0.0)
    assert np.all(s.wheel("My_Nm")[-1] < 0.0)  # rolling forward, against it
    assert np.any(s.wheel("Mx_Nm")[-1] != 0.0)


def _other_interpreters():
    """Pythons on this machine that are not the one vdyn was built for (a pyenv interpreter first
    on PATH, as on the development machine), at most one per version."""
    import glob
    import shutil
    from vdyn import _build
    built = os.path.realpath(_build.PYTHON)
    found = {}
    candidates = [shutil.which(n) for n in ("python3", "python")]
    candidates += sorted(glob.glob(os.path.expanduser("~/.pyenv/versions/3.*/bin/python3")))
    for path in filter(None, candidates):
        probe = subprocess.run([path, "-c", "import sys; print(sys.executable); "
                                "print('%d.%d' % sys.version_info[:2])"],
                               capture_output=True, text=True, timeout=60)
        if probe.returncode != 0:
            continue
        executable, version = probe.stdout.split()
        if os.path.realpath(executable) != built:
            found.setdefault(version, executable)
    return list(found.values())


def _import_vdyn(python, tmp_path):
    env = dict(os.environ, PYENV_VERSION="")
    return subprocess.run([python, "-c", "import vdyn"], capture_output=True, text=True,
                          timeout=120, cwd=str(tmp_path), env=env)


def test_another_interpreter_is_told_which_one_to_run(tmp_path):
    """Where python3 is not Debian's (pyenv's first on PATH), `import vdyn` says which
    interpreter this is, which one the module was built for, and what to run instead (it said
    "No module named 'numpy'")."""
    from vdyn import _build
    others = _other_interpreters()
    if not others:
        pytest.skip("no Python on this machine but the one vdyn was built for")
    for python in others:
        r = _import_vdyn(python, tmp_path)
        assert r.returncode != 0, f"{python} imported vdyn"
        last = r.stderr.strip().splitlines()[-1]
        assert last.startswith("ImportError: vdyn cannot be imported ("), r.stderr
        assert f"this interpreter is {python} (Python " in last, last
        assert f"the package was built for {_build.PYTHON} (Python {_build.PYTHON_VERSION})" in last
        assert f"Run {_build.PYTHON} instead (for example: {_build.PYTHON} -c 'import vdyn')" in last
        assert f"cmake -DPython3_EXECUTABLE={python}" in last


def test_a_venv_without_the_system_site_packages_is_told_what_to_make(tmp_path):
    """The same interpreter in a venv that cannot see Debian's numpy and protobuf."""
    from vdyn import _build
    venv = tmp_path / "bare"
    subprocess.run([_build.PYTHON, "-m", "venv", "--without-pip", str(venv)], check=True,
                   timeout=120)
    r = _import_vdyn(str(venv / "bin" / "python"), tmp_path)
    assert r.returncode != 0
    last = r.stderr.strip().splitlines()[-1]
    assert f"this interpreter is {venv / 'bin' / 'python'} (Python " in last, r.stderr
    assert (f"a venv of {_build.PYTHON} without its site packages, where numpy and protobuf "
            f"are: make the venv with {_build.PYTHON} -m venv --system-site-packages DIR") in last
