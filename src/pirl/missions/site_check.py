"""``pirl site check``: load a site, say what can be covered and why the rest cannot, draw it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pirl._atomic import replacing
from pirl.config.grid import ZOOM_RANGE
from pirl.config.mission import MissionSettings
from pirl.config.world import VCPPConfig
from pirl.world.seeable import REASONS, Seeability, analyse, lens_for
from pirl.world.site import Site, load_site

REASON_TEXT = {
    "hidden": "no free cell sees it with any camera pose (narrow courtyard, hidden by buildings)",
    "no_fly": "seen only from inside no-fly zones",
    "unreachable": "seen only from cells the UAV cannot reach from a start (enclosed)",
}
"""What each reason of :data:`pirl.world.seeable.REASONS` means, for people."""

COLOURS = {
    "ground": (236, 236, 228),
    "outside": (200, 200, 200),
    "no_fly": (230, 80, 60),
    "start": (40, 110, 230),
    "hidden": (200, 0, 200),
    "unreachable": (120, 40, 160),
    "no_fly_unseen": (255, 160, 0),
}


def gsd_cm(height_m: float | np.ndarray, zoom: float, m: MissionSettings) -> float | np.ndarray:
    """Ground sample distance, centimetres per pixel, of a nadir photo from ``height_m`` above
    the ground at ``zoom`` (the focal length times the zoom)."""
    return 100.0 * m.sensor_width_mm * height_m / (m.focal_length_mm * zoom * m.image_width_px)


def ground_report(site: Site, m: MissionSettings) -> dict[str, Any]:
    """The ground's figures: elevation range, slope and the ground sample distance range.

    The camera flies ``(z + 1) x level_height_m`` above the terrain under it; the ground it
    sees beside that cell lies higher or lower by up to the terrain's fall to the
    neighbouring cells, so the heights above the seen ground span the lowest level less the
    largest rise to a neighbour, to the highest level plus the largest fall.
    """
    from scipy.ndimage import maximum_filter, minimum_filter

    from pirl.world.terrain import slope_deg

    t = site.terrain
    area = site.area
    slope = slope_deg(t, site.georef.cell_size_m)
    rise = float((maximum_filter(t, size=3, mode="nearest") - t)[area].max())
    fall = float((t - minimum_filter(t, size=3, mode="nearest"))[area].max())
    level = site.level_height_m
    low = max(level - rise, 0.5)  # a camera never closer than half a metre, for the figure
    high = site.size[2] * level + fall
    return {
        "ground": site.ground,
        "elevation_m": [round(float(t[area].min()), 2), round(float(t[area].max()), 2)],
        "slope_deg": {
            "mean": round(float(slope[area].mean()), 2),
            "max": round(float(slope[area].max()), 2),
        },
        "height_above_seen_ground_m": [round(low, 2), round(high, 2)],
        "gsd_cm_per_px": [
            round(float(gsd_cm(low, ZOOM_RANGE[1], m)), 3),
            round(float(gsd_cm(high, ZOOM_RANGE[0], m)), 3),
        ],
        "camera": f"{m.sensor_width_mm:g} mm sensor, {m.focal_length_mm:g} mm lens at zoom 1, "
        f"{m.image_width_px} px across (mission.sensor_width_mm, focal_length_mm, "
        "image_width_px)",
    }


def check_site(path: str | Path, env: VCPPConfig | None = None) -> tuple[Site, Seeability, dict]:
    """The site at ``path``, its seeability under ``env``'s camera (defaults: the paper's),
    and the report as a JSON-ready dict (``seeable`` plus every reason's count equals
    ``coverable``)."""
    site = load_site(path)
    cfg = (env or VCPPConfig()).replace(size=site.size, site="", ground_cells=0)
    seen = analyse(site, lens_for(cfg))
    free = ~site.blocked
    report: dict[str, Any] = {
        "site": site.name,
        "folder": str(site.folder),
        "size": list(site.size),
        "cell_size_m": site.georef.cell_size_m,
        "level_height_m": site.level_height_m,
        "georeferenced": site.georef.real,
        "footprint": cfg.footprint,
        "occlusion": bool(cfg.occlusion and cfg.footprint != "paper"),
        "coverable": seen.coverable,
        "seeable": int(seen.seeable.sum()),
        "unseeable": seen.counts,
        "blocked_share": round(float(site.blocked.mean()), 4),
        "no_fly_cells": int(site.no_fly.sum()),
        "starts": len(site.starts),
        "reachable_cells": int(seen.reachable.sum()),
        "free_cells": int(free.sum()),
        "usable": bool(seen.seeable.any()),
        **ground_report(site, MissionSettings()),
    }
    return site, seen, report


def picture(site: Site, seen: Seeability, path: Path, cell_px: int = 0) -> Path:
    """A top-down PNG: buildings grey by height, no-fly zones red, outside the area darker,
    starts blue, unseeable cells by reason, with a legend. Written atomically."""
    from PIL import Image, ImageDraw

    sx, sy, _ = site.size
    px = cell_px or max(2, min(12, 640 // max(sx, sy)))
    img = np.zeros((sx, sy, 3), dtype=np.float64)
    img[:] = COLOURS["ground"]
    img[~site.area] = COLOURS["outside"]
    top = max(float(site.heights.max()), 1e-9)
    tall = site.heights > 0
    shade = (170 - 130 * (site.heights / top))[..., None]
    img[tall] = np.repeat(shade, 3, axis=2)[tall]
    img[site.no_fly] = 0.55 * img[site.no_fly] + 0.45 * np.array(COLOURS["no_fly"])
    for k, name in enumerate(REASONS):
        key = "no_fly_unseen" if name == "no_fly" else name
        img[seen.reason == k] = COLOURS[key]
    img[site.starts[:, 0], site.starts[:, 1]] = COLOURS["start"]
    rgb = np.ascontiguousarray(img.transpose(1, 0, 2)[::-1]).astype(np.uint8)  # north up
    rgb = rgb.repeat(px, axis=0).repeat(px, axis=1)
    legend = [
        ("start", "start"), ("no_fly", "no-fly zone"), ("outside", "outside the area"),
        ("hidden", "unseeable: hidden"), ("no_fly_unseen", "unseeable: only from no-fly"),
        ("unreachable", "unseeable: unreachable"),
    ]  # fmt: skip
    width = max(rgb.shape[1], 260)
    canvas = Image.new("RGB", (width, rgb.shape[0] + 16 * len(legend) + 24), (255, 255, 255))
    canvas.paste(Image.fromarray(rgb), (0, 0))
    draw = ImageDraw.Draw(canvas)
    y = rgb.shape[0] + 4
    draw.text((4, y), f"{site.name}: {sx} x {sy} x {site.size[2]}, grey = buildings by height",
              fill=(0, 0, 0))  # fmt: skip
    for key, text in legend:
        y += 16
        draw.rectangle((4, y + 2, 14, y + 12), fill=COLOURS[key])
        draw.text((20, y), text, fill=(0, 0, 0))
    path = Path(path)
    with replacing(path) as tmp:
        canvas.save(tmp, format="PNG")
    return path


def site_report(
    path: str | Path, env: VCPPConfig | None = None, drawn: Path | None = None
) -> dict[str, Any]:
    """:func:`check_site`'s report; with ``drawn``, the :func:`picture` written there and its
    path in the report under ``picture``."""
    site, seen, report = check_site(path, env)
    if drawn is not None:
        report["picture"] = str(picture(site, seen, drawn))
    return report


__all__ = [
    "COLOURS",
    "REASON_TEXT",
    "check_site",
    "gsd_cm",
    "ground_report",
    "picture",
    "site_report",
]
