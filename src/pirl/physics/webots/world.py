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

import json
import math
from pathlib import Path

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
    """The .wbt text of scenario ``seed`` (see the module doc)."""
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
    lines = [f"#VRML_SIM {WEBOTS_VERSION} utf8", ""]
    lines += [f'EXTERNPROTO "{_PROTO}/{p}"' for p in _EXTERNPROTOS]
    lines += [
        "",
        "WorldInfo {",
        "  info [",
        f'    "PIRL scenario: size {sx}x{sy}x{sz}, seed {seed}, footprint {env_cfg.footprint}"',
        f'    "cell {_f(cell)} m, level height {_f(physics.level_height_m)} m; written by pirl"',
        "  ]",
        f'  title "PIRL {sx}x{sy}x{sz} seed {seed}"',
        "  basicTimeStep 8",
        "  defaultDamping Damping {",
        "    linear 0.5",
        "    angular 0.5",
        "  }",
        '  coordinateSystem "ENU"',
        "}",
        "Viewpoint {",
        # Looking down 45 degrees at the arena from its -x side (Webots cameras look along +x).
        f"  orientation 0 1 0 {_f(math.pi / 4)}",
        f"  position {_f(centre[0] - extent)} {_f(centre[1])} {_f(extent)}",
        '  follow "Mavic 2 PRO"',
        "}",
        "TexturedBackground {",
        "}",
        "TexturedBackgroundLight {",
        "}",
        "Floor {",
        f"  translation {_f(centre[0])} {_f(centre[1])} 0",
        f"  size {_f(sx * cell)} {_f(sy * cell)}",
        f"  tileSize {_f(cell)} {_f(cell)}",
        "}",
        "Mavic2Pro {",
        f"  translation {_f(start[0])} {_f(start[1])} {_f(start[2])}",
        "  rotation 0 0 1 0",
        f'  controller "{CONTROLLER}"',
        "  controllerArgs [",
        *(f"    {json.dumps(a)}" for a in args),
        "  ]",
        # Supervisor: the controller can quit the simulation when the episode ends.
        "  supervisor TRUE",
        "  cameraSlot [",
        "    Camera {",
        f"      width {_WIDTH}",
        f"      height {_HEIGHT}",
        "      near 0.2",
        f"      fieldOfView {_f(fov)}",
        "      zoom CameraZoom {",
        f"        minFieldOfView {_f(fov_min)}",
        f"        maxFieldOfView {_f(fov_max)}",
        "      }",
        "    }",
        "  ]",
        "}",
    ]
    for k, (cx, cy, cz, r) in enumerate(mission.obstacle_spheres_m()):
        lines += [
            "Solid {",
            f"  translation {_f(cx)} {_f(cy)} {_f(cz)}",
            "  children [",
            "    Shape {",
            "      appearance PBRAppearance {",
            "        baseColor 0.8 0.35 0.2",
            "        roughness 0.7",
            "        metalness 0",
            "      }",
            "      geometry Sphere {",
            f"        radius {_f(r)}",
            "        subdivision 3",
            "      }",
            "    }",
            "  ]",
            f'  name "obstacle {k}"',
            "  boundingObject Sphere {",
            f"    radius {_f(r)}",
            "  }",
            "}",
        ]
    return "\n".join(lines) + "\n"


def write_world(
    out: str | Path,
    env_cfg: VCPPConfig,
    seed: int,
    physics: PhysicsConfig | None = None,
    policy: str = "boustrophedon",
    config_path: str | Path | None = None,
    controller: bool = True,
) -> list[Path]:
    """Write the world (and, with ``controller``, its controller shim); the paths written.

    The shim goes to ``<project>/controllers/pirl_mavic/``, where ``<project>`` is the parent
    of the world's ``worlds`` folder (Webots' layout), else the world's own folder.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    text = world_text(env_cfg, seed, physics, policy, config_path)
    out.write_text(text)
    written = [out]
    if controller:
        project = out.parent.parent if out.parent.name == "worlds" else out.parent
        shim = project / "controllers" / CONTROLLER / f"{CONTROLLER}.py"
        shim.parent.mkdir(parents=True, exist_ok=True)
        shim.write_text(_SHIM)
        written.append(shim)
    return written


__all__ = ["CONTROLLER", "world_text", "write_world", "zoom_fov_range"]
