"""shadowcl: hard shadows with OpenCL, every method measured against the exact answer.

    shadows = prepare(scene_or_mesh, light, method="exact", bounds=None)   # once per scene and light
    mask    = shadows.mask(points, normals=None)                           # bool (N,), any number of times
    mask    = shadow_mask(scene_or_mesh, light, points, normals=None, method="exact", **params)
    image   = Renderer(scene, method="exact").render(light=None, camera=None)
    image   = render(scene, method="exact", width=960, height=540)
    counts  = shadow_counts(scene_or_mesh, lights, points, normals=None, weights=None, client=None)
    suns    = sun_lights(latitude, longitude, start=..., end=..., step="1h")   # extra "sun"
"""

from .device import Device, KernelBuildError, get_device, list_devices
from .geometry import Mesh
from .lights import DirectionalLight, PointLight
from .methods import methods
from .counts import shadow_counts, shadow_matrix
from .metrics import MaskError, mask_error
from .render import Renderer, render
from .scene import Scene
from .shadows import Shadows, prepare, shadow_mask
from .subdivision import SubdivisionSurface
from .sun import sun_lights
from .views import Camera, View

__all__ = [
    "Camera", "Device", "DirectionalLight", "KernelBuildError", "MaskError", "Mesh", "PointLight", "Renderer",
    "Scene", "Shadows", "SubdivisionSurface", "View", "get_device", "list_devices", "mask_error", "methods",
    "prepare", "render", "shadow_counts", "shadow_mask", "shadow_matrix", "sun_lights",
]
__version__ = "0.1.0"
