"""The device layer: choosing an OpenCL device, building kernel programs once, reusing kernel objects.

A :class:`Device` owns one context and one in-order queue. Programs are built once per
(device, kernel file, build options) and their kernel objects are kept, because PyOpenCL's
``program.name`` creates a new kernel object on every access.

Kernel sources are read from the ``kernels`` folder shipped inside the package, and their
``#include "x.h"`` lines are expanded here before the source reaches OpenCL. That makes the text
handed to the driver the whole program: any binary cache keyed on source and options (PyOpenCL's,
PoCL's) sees a header edit or a changed ``-D`` option as a different program, so it cannot serve a
stale binary.
"""

from __future__ import annotations

import os
import re
import threading
from pathlib import Path

import numpy as np
import pyopencl as cl

from . import kernels as _kernel_package
from .checks import available_host_bytes, check_memory

# kernels/ is installed as the package shadowcl.kernels (see setup.cfg), editable or not.
KERNEL_DIR = Path(_kernel_package.__file__).resolve().parent
# Buffers from this size up are checked against the host's free memory on a CPU device (reading it costs
# ~20 us, nothing beside allocating and touching this much).
HOST_CHECKED_BYTES = 64 << 20

NO_PLATFORM_MESSAGE = (
    "shadowcl found no OpenCL platform. Install PoCL's CPU driver with "
    "'pip install pocl-binary-distribution' (a dependency of shadowcl; reinstall shadowcl if it is "
    "missing), or install your GPU vendor's OpenCL driver (ICD), then check with 'shadowcl devices'."
)

# An include line, optionally followed by a // or /* */ comment.
_INCLUDE = re.compile(r'^[ \t]*#[ \t]*include[ \t]*"([^"]+)"[ \t]*(?://.*|/\*.*\*/[ \t]*)?$', re.MULTILINE)


class KernelBuildError(RuntimeError):
    """A kernel file failed to compile; the message carries the file name and the build log."""


def expand_includes(path: Path, include_dir: Path, _seen: frozenset = frozenset()) -> str:
    """Return the text of ``path`` with every ``#include "x.h"`` replaced by that header's text.

    Headers are looked up next to ``path`` first, then in ``include_dir``; each header is expanded once
    per chain (headers also carry include guards).
    """
    path = Path(path)
    text = path.read_text()

    def replace(match: re.Match) -> str:
        name = match.group(1)
        for candidate in (path.parent / name, include_dir / name):
            if candidate.is_file():
                key = str(candidate.resolve())
                if key in _seen:
                    return f"/* {name}: already included */"
                body = expand_includes(candidate, include_dir, _seen | {key})
                return f'#line 1 "{name}"\n{body}\n#line {text.count(chr(10), 0, match.start()) + 2} "{path.name}"'
        raise KernelBuildError(f"{path.name}: cannot find included header {name!r} in {include_dir}")

    return _INCLUDE.sub(replace, text)


def _platforms() -> list:
    try:
        platforms = cl.get_platforms()
    except cl.Error as error:  # PyOpenCL raises when the ICD loader finds nothing
        raise RuntimeError(NO_PLATFORM_MESSAGE) from error
    if not platforms:
        raise RuntimeError(NO_PLATFORM_MESSAGE)
    return platforms


def list_devices() -> list[tuple[str, str, cl.Device]]:
    """Every OpenCL device as ``(selector, description, device)``; ``selector`` is "platform:device"."""
    found = []
    for p_index, platform in enumerate(_platforms()):
        for d_index, device in enumerate(platform.get_devices()):
            kind = "/".join(name for name in ("CPU", "GPU", "ACCELERATOR") if device.type & getattr(cl.device_type, name)) or "other"
            found.append((f"{p_index}:{d_index}", f"{platform.name} / {device.name} [{kind}, {device.version}]", device))
    return found


def _select(selector: str) -> cl.Device:
    """A device from "P:D" (platform and device index) or a case-insensitive substring of its name."""
    devices = list_devices()
    for key, description, device in devices:
        if selector == key or selector.lower() in description.lower():
            return device
    choices = "\n  ".join(f"{key}  {description}" for key, description, _ in devices)
    raise ValueError(f"device: no OpenCL device matches {selector!r}; the devices are:\n  {choices}")


def _default_device() -> cl.Device:
    selector = os.environ.get("SHADOWCL_DEVICE") or os.environ.get("PYOPENCL_CTX")
    if selector:
        return _select(selector)
    devices = [device for _, _, device in list_devices()]
    if not devices:
        raise RuntimeError(NO_PLATFORM_MESSAGE)
    # A GPU when there is one (the kernels are written to run there too), else a CPU (PoCL), else any
    for kind in (cl.device_type.GPU, cl.device_type.CPU):
        of_kind = [device for device in devices if device.type & kind]
        if of_kind:
            return of_kind[0]
    return devices[0]


class Device:
    """One OpenCL device with its context, in-order queue, and built programs.

    ``Device()`` picks, in order: ``SHADOWCL_DEVICE`` or ``PYOPENCL_CTX`` (``"P:D"`` indices or a
    name substring), else the first GPU, else the first CPU device, else any device. ``Device("pthread")`` or
    ``Device(cl_device)`` picks explicitly. ``kernel_dir`` replaces the shipped kernels folder (tests).
    Kernel objects are shared and carry their arguments, so use one Device from one thread at a time
    (builds are locked; launches are not).
    """

    def __init__(self, device: "str | cl.Device | None" = None, kernel_dir: "Path | None" = None):
        if device is None:
            device = _default_device()
        elif isinstance(device, str):
            device = _select(device)
        elif not isinstance(device, cl.Device):
            raise TypeError(f"device: expected None, a selector string or a pyopencl.Device, got {type(device).__name__}")
        self.cl_device = device
        self.kernel_dir = Path(kernel_dir) if kernel_dir is not None else KERNEL_DIR
        self.context = cl.Context([device])
        self.queue = cl.CommandQueue(self.context)
        self._programs: dict[tuple[str, tuple[str, ...]], cl.Program] = {}
        self._kernels: dict[tuple[str, tuple[str, ...], str], cl.Kernel] = {}
        self._lock = threading.Lock()
        self._scratch: dict[str, cl.Buffer] = {}

    def __repr__(self) -> str:
        return f"Device({self.cl_device.name!r})"

    @property
    def name(self) -> str:
        """The OpenCL device's name."""
        return self.cl_device.name

    @property
    def max_alloc_bytes(self) -> int:
        """The largest single buffer the device allows (PoCL's figure follows the machine's free memory)."""
        return int(self.cl_device.max_mem_alloc_size)

    def program(self, filename: str, options: "tuple[str, ...] | list[str]" = ()) -> cl.Program:
        """The program built from ``kernels/filename`` with ``options``, built on first use."""
        options = tuple(options)
        key = (filename, options)
        with self._lock:
            program = self._programs.get(key)
            if program is None:
                program = self._build(filename, options)
                self._programs[key] = program
        return program

    def kernel(self, filename: str, name: str, options: "tuple[str, ...] | list[str]" = ()) -> cl.Kernel:
        """The kernel ``name`` of ``kernels/filename`` built with ``options``; one object per key."""
        options = tuple(options)
        key = (filename, options, name)
        kernel = self._kernels.get(key)
        if kernel is None:
            program = self.program(filename, options)
            with self._lock:
                kernel = self._kernels.setdefault(key, cl.Kernel(program, name))
        return kernel

    def _build(self, filename: str, options: tuple[str, ...]) -> cl.Program:
        path = self.kernel_dir / filename
        if not path.is_file():
            raise KernelBuildError(f"{filename}: no such kernel file in {self.kernel_dir}")
        source = expand_includes(path, self.kernel_dir)
        try:
            return cl.Program(self.context, source).build(options=list(options) + ["-cl-std=CL1.2"])
        except cl.RuntimeError as error:
            raise KernelBuildError(f"{filename} failed to build with options {list(options)}:\n{error}") from None

    # Buffers ---------------------------------------------------------------------------------------
    def to_device(self, array: np.ndarray) -> cl.Buffer:
        """A read-only device copy of ``array`` (made C-contiguous; empty arrays get a 1-element buffer)."""
        array = np.ascontiguousarray(array)
        flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        if array.nbytes == 0:
            array = np.zeros(1, dtype=array.dtype)
        return cl.Buffer(self.context, flags, hostbuf=array)

    def input_view(self, array: np.ndarray) -> cl.Buffer:
        """A read-only device buffer of ``array`` for one call's kernels: the host array itself where the
        device shares host memory (a CPU device: CL_MEM_USE_HOST_PTR, no copy of 1.2 M receivers' 58 MB),
        else a copy (on a discrete GPU a host pointer buffer would be read across the bus by every kernel).
        The caller keeps ``array`` alive and unchanged while the kernels run."""
        array = np.ascontiguousarray(array)
        if array.nbytes == 0 or not self.shares_host_memory:
            return self.to_device(array)
        return cl.Buffer(self.context, cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=array)

    @property
    def shares_host_memory(self) -> bool:
        """The device's buffers are host memory (CL_DEVICE_HOST_UNIFIED_MEMORY, or a CPU device)."""
        return bool(self.cl_device.type & cl.device_type.CPU) or bool(self.cl_device.host_unified_memory)

    def empty(self, nbytes: int, what: str = "buffer") -> cl.Buffer:
        """An uninitialised read-write buffer; raises ``ValueError`` naming ``what`` if the device cannot hold it."""
        nbytes = max(int(nbytes), 1)
        if nbytes > self.max_alloc_bytes:
            raise ValueError(
                f"{what}: needs {nbytes / 2**20:.0f} MiB in one buffer but {self.name} allows at most "
                f"{self.max_alloc_bytes / 2**20:.0f} MiB; lower the resolution"
            )
        if nbytes >= HOST_CHECKED_BYTES and self.cl_device.type & cl.device_type.CPU:
            # a CPU device's buffers are host memory, and PoCL crashes (not fails) when the host runs out
            check_memory(what, f"a {nbytes / 2**20:.0f} MiB buffer", nbytes, available_host_bytes(), "the host")
        return cl.Buffer(self.context, cl.mem_flags.READ_WRITE, nbytes)

    def scratch(self, key: str, nbytes: int) -> cl.Buffer:
        """A read-write buffer of at least ``nbytes`` kept under ``key`` for the next call that asks for it.

        For a hot path's temporaries: a fresh buffer of tens of MiB costs its first touch of every page
        in the kernel that writes it (measured: a 38 MiB receiver buffer took 10-20 ms of page faults
        per call on PoCL). The buffer grows to the largest size asked and is kept while the device is
        (one user at a time, as the kernels are); its contents are whatever the last user left.
        """
        buffer = self._scratch.get(key)
        if buffer is None or buffer.size < nbytes:
            buffer = self.empty(nbytes, key)
            self._scratch[key] = buffer
        return buffer

    def from_device(self, buffer: cl.Buffer, shape, dtype) -> np.ndarray:
        """A new host array of ``shape`` and ``dtype`` copied from the start of ``buffer`` (blocking)."""
        out = np.empty(shape, dtype=dtype)
        if out.nbytes:
            cl.enqueue_copy(self.queue, out, buffer)
        return out


_default: Device | None = None


def get_device(device: "Device | str | cl.Device | None" = None) -> Device:
    """``device`` if it is a :class:`Device`, a new one for a selector, else the shared default device."""
    global _default
    if isinstance(device, Device):
        return device
    if device is not None:
        return Device(device)
    if _default is None:
        _default = Device()
    return _default
