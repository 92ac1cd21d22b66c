"""vdyn: the Python client of the vdyn vehicle-dynamics server (clients/python/README.md).

    import vdyn
    sim = vdyn.Client(domain=0)              # a running vdyn-server (--lockstep for lockstep)
    states = sim.step(1000, vdyn.make_input(steer=0.05, cruise_kmh=60), vehicle_id=1)[1]
"""

from . import _vdyn  # noqa: F401  (the extension module; fails here when it is missing)
from ._errors import Error, RecordingError, RefusedError, TimeoutError, TransportError
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
           "Error", "TimeoutError", "RefusedError", "RecordingError", "TransportError", "pb",
           "DEFAULT_TIMEOUT"]
