"""shadowcl: hard shadows with OpenCL, every method measured against the exact answer.

    shadows = prepare(scene_or_mesh, light, method="exact", bounds=None)   # once per scene and light
    mask    = shadows.mask(points, normals=None)                           # bool (N,), any number of times
    mask    = shadow_mask(scene_or_mesh, light, points, normals=None, method="exact", **params)
    image   = Renderer(scene, method="exact").render(light=None, camera=None)
    image   = render(scene, method="exact", width=960, height=540)
"""

from .device import Device, KernelBuildError, get_device, list_devices
from .geometry import Mesh
from .lights import DirectionalLight, PointLight
from .methods import methods
from .metrics import MaskError, mask_error
from .render import Renderer, render
from .scene import Scene
from .shadows import Shadows, prepare, shadow_mask
from .subdivision import SubdivisionSurface
from .views import Camera, View

__all__ = [
    "Camera", "Device", "DirectionalLight", "KernelBuildError", "MaskError", "Mesh", "PointLight", "Renderer",
    "Scene", "Shadows", "SubdivisionSurface", "View", "get_device", "list_devices", "mask_error", "methods",
    "prepare", "render", "shadow_mask",
]
__version__ = "0.1.0"
