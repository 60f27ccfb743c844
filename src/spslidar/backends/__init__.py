"""Array backends: where the numeric core runs (``--backend numpy|torch|cupy --device cpu|cuda``).

NumPy is the default and the only required dependency. There is one chain,
:func:`spslidar.pipeline.chain.measure` and ``reconstruct``, for every backend: on another
one the patterns live on its device, and each stage runs there when it has a device kernel
(:mod:`spslidar.backends.device`, written against the Python array API with
:mod:`spslidar.backends.kernels`, so PyTorch (CPU or CUDA), CuPy (CUDA) and
``array-api-strict``, the tests' strict namespace with fake devices, all work), or else runs
its NumPy implementation on the host through the same chain, so every stage choice runs on
every backend. Device kernels: the simulation with the ``linear`` detector, the centred QCR
problem, FISTA with TV (a CUDA graph on PyTorch + CUDA) and the argmax depth.

This module imports nothing numeric: the config validates ``backend`` and ``device`` here
without importing NumPy, and a GPU library is imported only when a run asks for it.

Random streams
--------------
The code, the range-gate probe and the regularisation-weight probe are drawn on the host with
NumPy from the seed's ``SeedSequence`` children, as in the NumPy path. The patterns and the
photon counts are drawn by :class:`spslidar.backends.rng.Stream`:

* ``numpy``, ``array-api-strict``: NumPy's generators, split exactly as the NumPy path splits
  them (the same patterns; the same Poisson streams per block of 64 patterns), so a run gives
  the NumPy path's depth map up to float32 round-off of the means;
* ``torch``: ``torch.Generator`` on the run's device, seeded from the same ``SeedSequence``
  children; ``cupy``: ``cupy.random.RandomState`` likewise.

Results are reproducible per backend and device (same seed, same library version: the same
numbers), not bitwise across them: compare backends by their depth RMSE statistics over seeds.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from typing import Any

from ..errors import ConfigError

#: backends a run may ask for (``array-api-strict`` is the tests' strict namespace)
BACKENDS = ("numpy", "torch", "cupy", "array-api-strict")
#: devices a run may ask for
DEVICES = ("cpu", "cuda")
#: the package that provides each backend, and the install hint for it
_PROVIDER = {
    "torch": ("torch", "PyTorch", "pip install -e \".[gpu]\" in a checkout (spslidar[gpu])"),
    "cupy": ("cupy", "CuPy",
             "pip install -e \".[cupy]\" in a checkout (or the cupy wheel for your CUDA)"),
    "array-api-strict": ("array_api_strict", "array-api-strict", "pip install array-api-strict"),
}
#: the stage choices with a device kernel (:mod:`spslidar.backends.device`); every other choice
#: runs its NumPy implementation on the host, through the same chain
DEVICE_KERNELS = {
    "solver": ("fista",),
    "regulariser": ("auto", "tv", "tv-aniso"),
    "qcr_form": ("centred",),
    "detector": ("linear",),
    "depth": ("argmax",),
}


def check_backend(backend: str, device: str) -> None:
    """Raise :class:`ConfigError` (one line) unless ``backend`` on ``device`` can run here.

    Imports the backend's library only when it is not NumPy, and only to ask whether CUDA is
    there.

    Parameters
    ----------
    backend : str
        One of :data:`BACKENDS`.
    device : str
        One of :data:`DEVICES`.
    """
    if backend not in BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if device not in DEVICES:
        raise ConfigError(f"unknown device {device!r}; choose one of {', '.join(DEVICES)}")
    if backend in ("numpy", "array-api-strict"):
        if device != "cpu":
            raise ConfigError(f"--backend {backend} runs on the CPU only; --device cuda needs "
                              f"--backend torch or cupy")
    if backend == "numpy":
        return
    module, name, hint = _PROVIDER[backend]
    if importlib.util.find_spec(module) is None or importlib.util.find_spec(
            "array_api_compat") is None:
        raise ConfigError(f"--backend {backend} needs {name} and array-api-compat: {hint}")
    if backend == "cupy" and device != "cuda":
        raise ConfigError("--backend cupy runs on CUDA only: add --device cuda")
    if device == "cuda" and not cuda_available(backend):
        raise ConfigError(f"--device cuda: {name} sees no CUDA GPU on this machine")


def cuda_available(backend: str) -> bool:
    """Whether ``backend`` (``torch`` or ``cupy``) can use a CUDA device here."""
    try:
        if backend == "torch":
            import torch

            return bool(torch.cuda.is_available())
        if backend == "cupy":
            import cupy

            return cupy.cuda.runtime.getDeviceCount() > 0
    except Exception:  # noqa: BLE001 - a broken driver or library is "no CUDA"
        return False
    return False


@dataclass(frozen=True)
class Backend:
    """A namespace and a device: where the arrays of a run live.

    Attributes
    ----------
    name : str
        One of :data:`BACKENDS`.
    xp : module
        The array-API namespace (``array_api_compat``'s wrapper for NumPy, PyTorch, CuPy).
    device : object
        The namespace's device object (``torch.device('cuda')``, ...).
    """

    name: str
    xp: Any
    device: Any

    def asarray(self, a: Any, dtype: Any = None) -> Any:
        """``a`` (host or device) as an array of this backend on its device."""
        if self.name == "torch":  # a NumPy array: straight to the device, no host copy
            import torch

            if not isinstance(a, torch.Tensor):
                import numpy as np

                a = torch.from_numpy(np.ascontiguousarray(a))
            a = a.to(self.device)
            return a if dtype is None else a.to(dtype)
        return self.xp.asarray(a, dtype=dtype, device=self.device)

    def to_numpy(self, a: Any) -> Any:
        """A device array as a NumPy array on the host."""
        import numpy as np

        if self.name == "torch":
            return a.detach().cpu().numpy()
        if self.name == "cupy":
            return a.get()
        if self.name == "array-api-strict":
            return np.asarray(self.xp.asarray(a, device=self.xp.Device("CPU_DEVICE")))
        return np.asarray(a)

    def sync(self) -> None:
        """Wait for the device's queued work (for honest timings)."""
        if self.name == "torch" and self.device.type == "cuda":
            import torch

            torch.cuda.synchronize(self.device)
        elif self.name == "cupy":
            import cupy

            cupy.cuda.get_current_stream().synchronize()


def get_backend(name: str, device: str = "cpu") -> Backend:
    """The :class:`Backend` for a config's ``backend`` and ``device`` (checked first)."""
    check_backend(name, device)
    if name == "numpy":
        import array_api_compat.numpy as xp

        return Backend(name, xp, "cpu")
    if name == "torch":
        import array_api_compat.torch as xp
        import torch

        return Backend(name, xp, torch.device(device))
    if name == "cupy":
        import array_api_compat.cupy as xp
        import cupy

        return Backend(name, xp, cupy.cuda.Device())
    import array_api_strict as xp

    # a non-default fake device: any array that strays to the default device fails loudly
    return Backend(name, xp, xp.Device("device1"))


def is_available(name: str, device: str = "cpu") -> bool:
    """Whether :func:`check_backend` accepts ``name`` on ``device`` here."""
    try:
        check_backend(name, device)
    except ConfigError:
        return False
    return True
