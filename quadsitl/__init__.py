"""quadsitl: a MAVLink-speaking software-in-the-loop quadrotor simulator."""

__version__ = "0.1.0"

from quadsitl.compiled_cache import drop_stale as _drop_stale_compiled_code
from quadsitl.registration import register_envs as _register_envs

_drop_stale_compiled_code()  # before anything is compiled: numba misses edits elsewhere
_register_envs()
