"""Scenes: per-pixel depth (metres), reflectivity and ground-truth validity.

Built-in scenes need no network: they use images shipped inside scikit-image or are synthesised.

* ``camera`` (default): stand-in for the paper's 'airplane' (Fig. 2a, 20-20.8 m), the
  ``skimage.data.camera`` grey image mapped linearly onto the depth window.
* ``motorcycle``: stand-in for the paper's 'doll' (Fig. 6a), the Middlebury 2014 "Motorcycle"
  ground-truth disparity in ``skimage.data.stereo_motorcycle`` converted to metres.
* ``steps``: a back plane with raised rectangles and a disc at distinct depths.
* ``ramp``: a smooth linear ramp with a sphere-like bump.
* ``room``: a wide-depth indoor scene (2-5 m): a receding floor, a slanted side wall, a table
  on thin legs, a thin lamp pole, a dark cabinet and a dark poster on the back wall.
* ``street``: a wide-depth outdoor scene (2-5 m): a receding road, a slanted facade with dark
  windows, a parked car, three thin poles (one dark), a slanted thin wire and a dark far
  backdrop.

A thin structure (here, in ``fence`` and in ``procedural:SEED``) is ``max(1/64, 1/N)`` of the
side of an ``N x N`` scene wide: from 64 x 64 up a fixed width in the scene, one pixel at
64 x 64 and ``N / 64`` pixels above (2 at 128, 8 at 512); one pixel at every size below 64.

User scenes are read from ``.npy``, ``.npz`` or grey images (``.png``, ``.tif``, ``.tiff``,
``.jpg``, ``.jpeg``); see :func:`load_scene`.

The built-ins are the entries of the registry :data:`SCENES` (name -> a function
``make(size, depth_min, depth_max)`` returning a :class:`Scene`); an entry registered with
``argument="SEED"`` (say) is a parametrised kind, written ``kind:ARG`` and built by
``make(size, depth_min, depth_max, arg)``. Adding a scene kind is one module plus one
:meth:`~spslidar.registry.Registry.add` line here. The package: :mod:`.base` (the
:class:`Scene` and the resampling), :mod:`.builtin` (the built-ins), :mod:`.files` (user files).
"""

from __future__ import annotations

from ..registry import Registry, lazy_exports

__all__ = [
    "BUILTIN_SCENES",
    "DEFAULT_SCENE",
    "MAX_SCENE_DEPTH_M",
    "SCENES",
    "SCENE_FILE_SUFFIXES",
    "Scene",
    "footprints",
    "load_scene",
    "motorcycle_source",
    "scene_spec",
]

# the scenes import numpy: re-exported on first access (the registry stays light, so
# ``spslidar --help`` lists the scenes without importing numpy)
__getattr__ = lazy_exports(__name__, {
    "MAX_SCENE_DEPTH_M": "base", "SCENE_FILE_SUFFIXES": "base", "Scene": "base",
    "footprints": "base", "load_scene": "load", "motorcycle_source": "builtin",
    "scene_spec": "load"})

#: the built-in scene kinds (the ``scene`` config key / ``--scene``), by name
SCENES = Registry("scene", "scene", takes_options=False, takes_defaults=True)
SCENES.add("camera", "spslidar.scenes.builtin:_camera", "camera",
           "skimage's camera image as depth, 20-20.8 m (the paper's 'airplane'; default)")
SCENES.add("motorcycle", "spslidar.scenes.builtin:_motorcycle", "motorcycle",
           "Middlebury 2014 disparity as depth, 2.1-4.7 m (the paper's 'doll')")
SCENES.add("steps", "spslidar.scenes.builtin:_steps", "steps",
           "raised rectangles and a disc on a back plane, 10-10.6 m")
SCENES.add("ramp", "spslidar.scenes.builtin:_ramp", "ramp",
           "a linear ramp with a bump, 5-5.5 m")
SCENES.add("room", "spslidar.scenes.builtin:_room", "room",
           "wide-depth indoor scene, 2-5 m: floor, slanted wall, one-pixel legs and pole")
SCENES.add("street", "spslidar.scenes.builtin:_street", "street",
           "wide-depth outdoor scene, 2-5 m: road, slanted facade, poles, a wire")
SCENES.add("fence", "spslidar.scenes.procgen:fence_scene", "fence",
           "a wire-mesh fence at 3 m in front of a wall at 4 m: two surfaces per mesh pixel")
SCENES.add("procedural", "spslidar.scenes.procgen:procedural_scene", "procedural",
           "a seeded wide-depth room, street or clutter scene (poles, wires, legs, fences, "
           "boxes; reflectivity 0.05-1)", argument="SEED")

#: Names of the built-in scenes without an argument (the first is the default).
BUILTIN_SCENES: tuple[str, ...] = tuple(e.name for e in SCENES if not e.defaults.get("argument"))
#: The default scene.
DEFAULT_SCENE = "camera"


def _scene_names() -> list[str]:
    return [f"{e.name}:{e.defaults['argument']}" if e.defaults.get("argument") else e.name
            for e in SCENES]


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
