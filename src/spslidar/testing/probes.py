"""The probes the conformance checks build a stage's output from (:mod:`.stages`), and a
fresh interpreter builds again (:mod:`.process`): the config of a code family's probe, its
code maker, and a scene kind's spec and size. Their own module, so that both import it and
neither the other back.
"""

from __future__ import annotations

import numpy as np

from ..config import Config, chosen_stage_options
from ..errors import ConfigError
from . import config_for

__all__ = ["probe_code", "scene_size", "scene_spec"]

#: candidate code lengths; the first one a family accepts is used
CODE_LENGTHS = (127, 255, 511, 1023, 128)


def _fail(what: str, why: str) -> AssertionError:
    return AssertionError(f"{what}: {why}")


def _probe(option: str, name: str) -> dict:
    """The config overrides an entry declares for its checks (``check={"size": 16}``): a
    stage that needs other sizes than the probe's says so where it is registered."""
    from . import registry_of

    probe = registry_of(option).get(name).defaults.get("check", {})
    if not isinstance(probe, dict):
        raise AssertionError(f"{option} {name!r}: its entry's check= must be a dict of config "
                             f"keys, got {probe!r}")
    return dict(probe)


def _code_config(name: str) -> Config:
    probe = _probe("code", name)
    if "code_length" in probe:
        return config_for("code", name, **probe)
    for length in CODE_LENGTHS:
        try:
            return config_for("code", name, code_length=length)
        except ConfigError:
            continue
    raise _fail(f"code family {name!r}", f"accepts none of the probe's lengths "
                                         f"{CODE_LENGTHS}; declare one it accepts with "
                                         f"check={{'code_length': L}} where it is registered")


def probe_code(name: str):
    """``(make, index, length)``: the probe's maker of family ``name``'s code,
    ``make(index)``, the entry's default index and the length it asks for, as
    :func:`check_code_family` builds them."""
    from ..codes import CODES

    cfg = _code_config(name)
    entry = CODES.get(name)
    options = chosen_stage_options(cfg, "code")
    length = cfg.code_length

    def make(index):
        return np.asarray(entry.load()(name, length, 0.5, rng=np.random.default_rng(1),
                                       index=index, **options))

    return make, entry.defaults.get("index", 0), length


def scene_spec(name: str) -> str:
    """A loadable spec of scene kind ``name`` (``kind:EXAMPLE`` where it takes an argument)."""
    from ..scenes import SCENES

    entry = SCENES.get(name)
    if entry.defaults.get("argument"):
        return f"{name}:{entry.defaults.get('example', '0')}"
    return name


def scene_size(name: str) -> int:
    """The probe's side for scene kind ``name`` (16, or its entry's ``check={"size": N}``)."""
    return int(_probe("scene", name).get("size", 16))
