"""dpm: deep photon mapping — caustics from few photons with a learned density kernel."""

from dpm.camera import Camera
from dpm.errors import InputError
from dpm.scene import Scene, load_scene

__all__ = ["Camera", "InputError", "Scene", "load_scene"]
__version__ = "0.1.0"
