"""A Webots world for one scenario: Mavic 2 Pro with a zoom camera, sphere obstacles, a floor.

``pirl webots-world --size 30 30 3 --seed 0 --out project/worlds/world.wbt`` writes the world
and, next to it, the controller that flies a PIRL policy in it
(``project/controllers/pirl_mavic/pirl_mavic.py``, a shim around
:mod:`pirl.physics.webots.controller`). The obstacles and the start are those of
``VCPPEnv.reset(seed=seed)``, placed with the same metric layout as the PyFlyt backend
(:class:`~pirl.physics.flight.Mission`), so the three simulators fly the same scenario.

Needs no Webots to run (text only); the world targets Webots R2023b (ENU coordinates).
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import jinja2

from pirl.config.physics import PhysicsConfig
from pirl.config.world import VCPPConfig
from pirl.physics.flight import Mission

WEBOTS_VERSION = "R2023b"
CONTROLLER = "pirl_mavic"
_PROTO = "https://raw.githubusercontent.com/cyberbotics/webots/" + WEBOTS_VERSION + "/projects"
_EXTERNPROTOS = (
    "objects/backgrounds/protos/TexturedBackground.proto",
    "objects/backgrounds/protos/TexturedBackgroundLight.proto",
    "objects/floors/protos/Floor.proto",
    "robots/dji/mavic/protos/Mavic2Pro.proto",
)
# Camera resolution with the frustum model's 4:3 aspect.
_WIDTH, _HEIGHT = 400, 300

_SHIM = '''"""Webots controller: a PIRL policy flies the Mavic 2 Pro (written by pirl webots-world).

Webots must run it with a Python that has pirl installed: set Tools > Preferences >
Python command to the project's .venv/bin/python (see docs/physics.md).
"""

import sys

from pirl.physics.webots.controller import main

main(sys.argv[1:])
'''


def _f(x: float) -> str:
    """A number as Webots writes it: short, no trailing zeros."""
    return f"{x:.6g}"


def zoom_fov_range(fov_deg: float) -> tuple[float, float]:
    """(min, max) horizontal field of view, radians, over the zoom range 2.0 .. 0.5."""
    half = math.tan(math.radians(fov_deg) / 2.0)
    return 2.0 * math.atan(half / 2.0), 2.0 * math.atan(half / 0.5)


def world_text(
    env_cfg: VCPPConfig,
    seed: int,
    physics: PhysicsConfig | None = None,
    policy: str = "boustrophedon",
    config_path: str | Path | None = None,
    log_path: str = "pirl_webots_episodes.jsonl",
) -> str:
    """The .wbt text of scenario ``seed`` (see the module doc), rendered from
    ``templates/world.wbt.j2``."""
    physics = physics or PhysicsConfig(cell_size_m=2.0, level_height_m=2.0, body_radius_m=0.25)
    mission = Mission(env_cfg, physics)
    mission.reset(seed)
    sx, sy, sz = env_cfg.size
    cell = physics.cell_size_m
    centre = ((sx - 1) / 2.0 * cell, (sy - 1) / 2.0 * cell)
    extent = max(sx, sy) * cell
    start = mission.cell_position(mission.start)
    fov = math.radians(env_cfg.fov_deg)
    fov_min, fov_max = zoom_fov_range(env_cfg.fov_deg)
    args = [
        "--policy", str(policy), "--size", str(sx), str(sy), str(sz), "--seed", str(seed),
        "--cell-size", _f(cell), "--level-height", _f(physics.level_height_m),
        "--footprint", env_cfg.footprint, "--out", log_path,
    ]  # fmt: skip
    if config_path is not None:
        args += ["--config", str(config_path)]
    return _template().render(
        version=WEBOTS_VERSION,
        protos=[f"{_PROTO}/{p}" for p in _EXTERNPROTOS],
        sx=sx, sy=sy, sz=sz, seed=seed, footprint=env_cfg.footprint,
        cell=cell, level_height=physics.level_height_m, pi=math.pi,
        centre=centre, extent=extent, start=start,
        controller=CONTROLLER, args=args,
        width=_WIDTH, height=_HEIGHT, fov=fov, fov_min=fov_min, fov_max=fov_max,
        spheres=mission.obstacle_spheres_m(),
    )  # fmt: skip


@functools.cache
def _template() -> jinja2.Template:
    """``templates/world.wbt.j2``: numbers through ``n`` (:func:`_f`), strings through
    ``json`` (Webots strings are JSON's; Jinja's ``tojson`` would escape HTML characters)."""
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("pirl.physics.webots", "templates"),
        autoescape=False,  # a .wbt file, not HTML
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    env.filters["n"] = _f
    env.filters["json"] = json.dumps
    return env.get_template("world.wbt.j2")


def write_world(
    out: str | Path,
    env_cfg: VCPPConfig,
    seed: int,
    physics: PhysicsConfig | None = None,
    policy: str = "boustrophedon",
    config_path: str | Path | None = None,
    controller: bool = True,
) -> list[Path]:
    """Write the world (and, with ``controller``, its controller shim; with ``config_path``,
    the env settings there for the controller to read); the paths written.

    The shim goes to ``<project>/controllers/pirl_mavic/``, where ``<project>`` is the parent
    of the world's ``worlds`` folder (Webots' layout), else the world's own folder.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    text = world_text(env_cfg, seed, physics, policy, config_path)
    out.write_text(text)
    written = [out]
    if config_path is not None:  # the env settings the controller reads (its own --config)
        import yaml

        Path(config_path).write_text(yaml.safe_dump(env_cfg.to_dict(), sort_keys=False))
        written.append(Path(config_path))
    if controller:
        project = out.parent.parent if out.parent.name == "worlds" else out.parent
        shim = project / "controllers" / CONTROLLER / f"{CONTROLLER}.py"
        shim.parent.mkdir(parents=True, exist_ok=True)
        shim.write_text(_SHIM)
        written.append(shim)
    return written


def write_mavic_world(
    out: Path,
    env_cfg: VCPPConfig,
    seed: int,
    policy: str = "boustrophedon",
    cell_size_m: float = 2.0,
    env_beside: bool = False,
    controller: bool = True,
) -> list[Path]:
    """``pirl webots-world``: :func:`write_world` at the Mavic's scale (cells and levels of
    ``cell_size_m``); with ``env_beside``, the env settings written as ``<world>.env.yaml``.
    The paths written."""
    physics = PhysicsConfig(cell_size_m=cell_size_m, level_height_m=cell_size_m, body_radius_m=0.25)
    # The controller reads env settings alone (its own --config), so it gets the preset's env
    # section as a file of its own, by absolute path (Webots runs it in its own folder).
    env_file = out.with_name(f"{out.stem}.env.yaml").resolve() if env_beside else None
    return write_world(out, env_cfg, seed, physics, policy, env_file, controller)


__all__ = ["CONTROLLER", "world_text", "write_mavic_world", "write_world", "zoom_fov_range"]
