"""WMO: a 3D rigid-body collision and physics engine."""
from . import _core

__version__ = "0.1.0"
