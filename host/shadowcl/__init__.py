"""shadowcl: hard shadows with OpenCL, every method measured against the exact answer.

    mask  = shadow_mask(scene_or_mesh, light, points, normals=None, method="exact", **params)
    image = render(scene, method="exact", width=960, height=540)
"""

from .device import Device, KernelBuildError, get_device, list_devices
from .geometry import Mesh
from .lights import DirectionalLight, PointLight
from .methods import methods, shadow_mask
from .metrics import MaskError, mask_error
from .render import render
from .scene import Scene
from .subdivision import SubdivisionSurface
from .views import Camera, View

__all__ = [
    "Camera", "Device", "DirectionalLight", "KernelBuildError", "MaskError", "Mesh", "PointLight",
    "Scene", "SubdivisionSurface", "View", "get_device", "list_devices", "mask_error", "methods", "render", "shadow_mask",
]
__version__ = "0.1.0"
