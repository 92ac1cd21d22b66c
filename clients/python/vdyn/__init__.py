"""vdyn: the Python client of the vdyn vehicle-dynamics server (clients/python/README.md).

    import vdyn
    sim = vdyn.Client(domain=0)              # a running vdyn-server (--lockstep for lockstep)
    states = sim.step(1000, vdyn.make_input(steer=0.05, cruise_kmh=60), vehicle_id=1)[1]
"""

import sys as _sys

from . import _build


def _import_error(error):
    """The ImportError that says why vdyn cannot be imported by this interpreter: which
    interpreter this is, which one the module was built for, and what to run instead."""
    import os
    here = f"{_sys.executable} (Python {_sys.version.split()[0]}, prefix {_sys.prefix})"
    built = f"{_build.PYTHON} (Python {_build.PYTHON_VERSION})"
    venv = f"{_build.PYTHON} -m venv --system-site-packages DIR"
    same = os.path.realpath(_sys.executable) == os.path.realpath(_build.PYTHON)
    if same and _sys.prefix == _sys.base_prefix:
        advice = ("it is the interpreter vdyn was built for, without a package vdyn needs: "
                  "install Debian's python3-numpy and python3-protobuf (scripts/install-deps.sh)")
    elif same:
        advice = (f"a venv of {_build.PYTHON} without its site packages, where numpy and "
                  f"protobuf are: make the venv with {venv}, or run {_build.PYTHON}")
    else:
        advice = (f"the package was built for {built}, whose numpy and protobuf it uses. Run "
                  f"{_build.PYTHON} instead (for example: {_build.PYTHON} -c 'import vdyn'), or "
                  f"a venv made from it ({venv}); to build for this interpreter, configure with "
                  f"cmake -DPython3_EXECUTABLE={_sys.executable} (it needs pybind11, numpy and "
                  f"protobuf for it)")
    return ImportError(f"vdyn cannot be imported ({error}): this interpreter is {here}; {advice}.")


try:
    if f"{_sys.version_info[0]}.{_sys.version_info[1]}" != ".".join(
            _build.PYTHON_VERSION.split(".")[:2]):
        raise ImportError(f"a module for Python {_build.PYTHON_VERSION} does not load into "
                          f"Python {_sys.version.split()[0]}")
    import numpy  # noqa: F401
    import google.protobuf  # noqa: F401
    from . import _vdyn  # noqa: F401  (the extension module)
except ImportError as _e:
    raise _import_error(_e) from _e
from ._errors import (DiscardedStepsWarning, Error, RecordingError, RefusedError,
                      SeveralRunsWarning, TimeoutError, TransportError)
from ._states import COLUMNS, States
from ._client import DEFAULT_TIMEOUT, Client, Driver, Subscription, make_input
from ._recording import Recording
from . import (common_pb2, control_pb2, exact_pb2, input_pb2, session_pb2, state_pb2,
               vehicle_params_pb2, world_pb2)


class _Pb:
    """The generated message classes in one namespace: vdyn.pb.VehicleParams, ..."""

    def __init__(self):
        for mod in (common_pb2, control_pb2, exact_pb2, input_pb2, session_pb2, state_pb2,
                    vehicle_params_pb2, world_pb2):
            for name in mod.DESCRIPTOR.message_types_by_name:
                setattr(self, name, getattr(mod, name))
            for name in mod.DESCRIPTOR.enum_types_by_name:
                setattr(self, name, getattr(mod, name))


pb = _Pb()

__all__ = ["Client", "Driver", "Subscription", "Recording", "States", "COLUMNS", "make_input",
           "Error", "TimeoutError", "RefusedError", "RecordingError", "TransportError",
           "DiscardedStepsWarning", "SeveralRunsWarning", "pb", "DEFAULT_TIMEOUT"]
