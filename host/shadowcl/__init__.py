"""shadowcl: hard shadows with OpenCL, every method measured against the exact answer."""

from .device import Device, KernelBuildError, get_device, list_devices
from .geometry import Mesh
from .lights import DirectionalLight, PointLight
from .views import Camera, View

__all__ = [
    "Camera", "Device", "DirectionalLight", "KernelBuildError", "Mesh", "PointLight", "View",
    "get_device", "list_devices",
]
__version__ = "0.1.0"
