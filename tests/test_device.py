"""The device layer: selection, program builds and their caches, build errors."""

import numpy as np
import pyopencl as cl
import pytest

import shadowcl as sc
from shadowcl import device as device_module

VALUE_KERNEL = """
#include "value.h"
__kernel void write_value(__global int *out) { out[get_global_id(0)] = VALUE + HEADER_VALUE; }
"""


def run_value(dev: sc.Device, options=()) -> int:
    out = dev.empty(4)
    dev.kernel("value.cl", "write_value", options)(dev.queue, (1,), None, out)
    return int(dev.from_device(out, 1, np.int32)[0])


@pytest.fixture
def kernel_dir(tmp_path):
    (tmp_path / "value.cl").write_text(VALUE_KERNEL)
    (tmp_path / "value.h").write_text("#define HEADER_VALUE 100\n")
    return tmp_path


def test_default_device_prefers_gpu(monkeypatch):
    """Without a selector: the first GPU, else the first CPU, else any device; a selector wins."""
    class Fake:
        def __init__(self, name, kind):
            self.name, self.type = name, kind

    cpu, gpu, other = Fake("cpu", cl.device_type.CPU), Fake("gpu", cl.device_type.GPU), Fake("acc", cl.device_type.ACCELERATOR)
    monkeypatch.delenv("SHADOWCL_DEVICE", raising=False)
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    for devices, want in (([cpu, gpu], gpu), ([other, cpu], cpu), ([other], other)):
        monkeypatch.setattr(device_module, "list_devices",
                            lambda devices=devices: [(f"0:{i}", d.name, d) for i, d in enumerate(devices)])
        assert device_module._default_device() is want
    monkeypatch.setenv("SHADOWCL_DEVICE", "cpu")                 # told otherwise: the named device
    monkeypatch.setattr(device_module, "list_devices", lambda: [("0:0", "gpu", gpu), ("0:1", "cpu", cpu)])
    assert device_module._default_device() is cpu


def test_select_by_index_name_and_environment(monkeypatch):
    selector, description, cl_device = sc.list_devices()[0]
    assert sc.Device(selector).cl_device == cl_device
    assert sc.Device(cl_device.name[:6].upper()).cl_device == cl_device
    monkeypatch.setenv("SHADOWCL_DEVICE", selector)
    assert sc.Device().cl_device == cl_device


def test_bad_selectors():
    with pytest.raises(ValueError, match="device: no OpenCL device matches 'no-such-device'"):
        sc.Device("no-such-device")
    with pytest.raises(TypeError, match="device: expected"):
        sc.Device(3)


def test_no_platform_says_how_to_get_pocl(monkeypatch):
    monkeypatch.setattr(device_module.cl, "get_platforms", lambda: [])
    monkeypatch.delenv("SHADOWCL_DEVICE", raising=False)
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    with pytest.raises(RuntimeError, match="pocl-binary-distribution"):
        sc.Device()


def test_kernel_objects_are_reused(kernel_dir):
    dev = sc.Device(kernel_dir=kernel_dir)
    first = dev.kernel("value.cl", "write_value", ("-DVALUE=1",))
    assert dev.kernel("value.cl", "write_value", ("-DVALUE=1",)) is first
    assert dev.kernel("value.cl", "write_value", ("-DVALUE=2",)) is not first


def test_build_options_and_header_edits_are_never_served_stale(kernel_dir):
    # PoCL and PyOpenCL keep binary caches across processes; a changed -D option or header must rebuild.
    assert run_value(sc.Device(kernel_dir=kernel_dir), ("-DVALUE=1",)) == 101
    assert run_value(sc.Device(kernel_dir=kernel_dir), ("-DVALUE=2",)) == 102
    (kernel_dir / "value.h").write_text("#define HEADER_VALUE 200\n")
    assert run_value(sc.Device(kernel_dir=kernel_dir), ("-DVALUE=1",)) == 201


def test_build_error_names_file_and_carries_log(kernel_dir):
    (kernel_dir / "broken.cl").write_text("__kernel void broken(__global int *out) { out[0] = undefined_name; }\n")
    with pytest.raises(sc.KernelBuildError, match=r"broken\.cl(.|\n)*undefined_name"):
        sc.Device(kernel_dir=kernel_dir).program("broken.cl")


def test_missing_kernel_file_and_header(kernel_dir):
    dev = sc.Device(kernel_dir=kernel_dir)
    with pytest.raises(sc.KernelBuildError, match="nothing.cl: no such kernel file"):
        dev.program("nothing.cl")
    (kernel_dir / "needs.cl").write_text('#include "absent.h"\n')
    with pytest.raises(sc.KernelBuildError, match="cannot find included header 'absent.h'"):
        dev.program("needs.cl")


def test_buffer_larger_than_the_device_allows(device):
    with pytest.raises(ValueError, match="depth map: needs .* MiB in one buffer"):
        device.empty(device.max_alloc_bytes + 1, "depth map")


def test_include_with_trailing_comment(kernel_dir):
    source = VALUE_KERNEL.replace('#include "value.h"', '#include "value.h"  // HEADER_VALUE')
    (kernel_dir / "value.cl").write_text(source)
    assert run_value(sc.Device(kernel_dir=kernel_dir), ("-DVALUE=3",)) == 103


def test_input_view_shares_host_memory_only_where_the_device_does(device, monkeypatch):
    """A CPU device reads a call's inputs in place (CL_MEM_USE_HOST_PTR); a device with memory of its own
    (a discrete GPU) gets a copy; either way the kernels read the array's values."""
    array = np.arange(12, dtype=np.float64).reshape(4, 3)
    assert device.shares_host_memory == bool(device.cl_device.type & cl.device_type.CPU or
                                             device.cl_device.host_unified_memory)
    buffers = {}
    for shares in (True, False):
        monkeypatch.setattr(type(device), "shares_host_memory", property(lambda self, shares=shares: shares))
        buffers[shares] = device.input_view(array)
    assert buffers[True].flags & cl.mem_flags.USE_HOST_PTR and not buffers[True].flags & cl.mem_flags.COPY_HOST_PTR
    assert buffers[False].flags & cl.mem_flags.COPY_HOST_PTR and not buffers[False].flags & cl.mem_flags.USE_HOST_PTR
    for buffer in buffers.values():
        assert np.array_equal(device.from_device(buffer, (4, 3), np.float64), array)


LANE_ANY_KERNEL = """
#include "vecmath.h"
__kernel void lane_any(__global const int *masks, __global int *out)
{
    const int g = get_global_id(0);
    int m[LANES];
    for (int j = 0; j < LANES; ++j)
        m[j] = masks[LANES * g + j];
    const lint mask = LANE_LOAD(int, m);
    out[2 * g] = LANE_ANY(mask);
    out[2 * g + 1] = LANE_ANY_SWIZZLED(mask);
}
"""


@pytest.mark.parametrize("lanes", [4, 8])
def test_lane_any_matches_numpy_either_way(tmp_path, rng, lanes):
    """vecmath.h's LANE_ANY (a compiler builtin where there is one) and its swizzled fallback, on every
    single-lane mask, none and all, and random ones."""
    (tmp_path / "lane_any.cl").write_text(LANE_ANY_KERNEL)
    (tmp_path / "vecmath.h").write_text((device_module.KERNEL_DIR / "vecmath.h").read_text())
    dev = sc.Device(kernel_dir=tmp_path)
    masks = np.concatenate([np.zeros((1, lanes)), np.eye(lanes), np.ones((1, lanes)),
                            rng.random((200, lanes)) < 0.2]).astype(np.int32) * -1
    out = dev.empty(8 * len(masks))
    dev.kernel("lane_any.cl", "lane_any", (f"-DLANES={lanes}",))(dev.queue, (len(masks),), None,
                                                                 dev.to_device(masks), out)
    got = dev.from_device(out, (len(masks), 2), np.int32) != 0
    expected = masks.any(axis=1)
    assert np.array_equal(got[:, 0], expected) and np.array_equal(got[:, 1], expected)
