"""The dashboard's map and costmap layers, and the keepout zones painted on them.

Grids travel as tiles that change (see :class:`~eddiebot.viz.dashboard.core.TileCache`).
Keepout zones painted on the page go into a copy of the current keepout mask (the one on
``/keepout_filter_mask``, else an empty one shaped as ``/map``), which is written to a
map_server file and handed to the keepout filter mask server's ``load_map``: the server
publishes it and the costmaps' keepout filters take it.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.core.task import Future
from eddiebot.maps import OccupancyMap, map_from_msg, map_to_world, save_map
from eddiebot.viz.dashboard.core import GridMeta, binary_frame
from eddiebot.viz.dashboard.display import GRID_LAYERS, DisplayNode, _compose, _yaw

__all__ = ["GridLayers"]


class GridLayers(DisplayNode):
    """``/map``, the costmaps and rtabmap's grid as tiles; the keepout mask and its painting."""

    _mask_loader: Any
    _keepout: OccupancyMap | None
    _keepout_dir: Path | None
    _keepout_count: int

    def _on_grid(self, layer: str, msg: Any) -> None:
        info = msg.info
        o = info.origin
        meta = GridMeta(int(info.width), int(info.height), float(info.resolution),
                        (float(o.position.x), float(o.position.y), _yaw(o.orientation)),
                        msg.header.frame_id.lstrip("/") or "map")
        cells = np.asarray(msg.data, dtype=np.int8)
        if cells.size != meta.width * meta.height or meta.resolution <= 0:
            self._problems[GRID_LAYERS[layer]] = (
                f"grid of {cells.size} cells does not match {meta.width}x{meta.height}")
            return
        cache = self._tiles[layer]
        new_gen, tiles = cache.update(meta, cells.reshape(meta.height, meta.width))
        if new_gen:
            self._grid_meta[layer] = meta
            self.hub.drop_prefix(f"tile:{layer}:")
            self._post_grid_meta(layer)
        for tx, ty, w, h, data in tiles:
            self.hub.post(f"tile:{layer}:{tx}:{ty}", binary_frame(
                {"t": "tile", "layer": layer, "gen": cache.generation, "tx": tx, "ty": ty,
                 "w": w, "h": h, "tile": cache.tile}, data))

    def map_bounds(self) -> tuple[float, float, float, float] | None:
        """Axis-aligned bounds of ``/map`` in the display frame (m), if placed."""
        meta = self._grid_meta.get("map")
        placed = self._grid_placed.get("map")
        if meta is None or placed is None or placed[0] != self.display_frame:
            return None
        w, h = meta.width * meta.resolution, meta.height * meta.resolution
        pts = [_compose(placed[1], x, y, 0.0) for x, y in ((0, 0), (w, 0), (0, h), (w, h))]
        xs, ys = [p[0] for p in pts], [p[1] for p in pts]
        return min(xs), min(ys), max(xs), max(ys)

    def _on_keepout_mask(self, msg: Any) -> None:
        with self._cmd_lock:
            self._keepout = map_from_msg(msg)

    def _keepout_base(self) -> OccupancyMap | None:
        """The mask to paint on: the current keepout mask, else an empty one shaped as /map."""
        if self._keepout is not None:
            return self._keepout
        meta = self._grid_meta.get("map")
        if meta is None:
            return None
        return OccupancyMap(np.zeros((meta.height, meta.width), np.int8), meta.resolution,
                            meta.origin, meta.frame_id)

    def paint_keepout(self, rect: tuple[float, float, float, float] | None,
                      done: Callable[[bool, str], None]) -> None:
        """Mark the cells of ``rect`` (x0, y0, x1, y1 in the display frame, m) occupied in the
        keepout mask, or clear the mask (``rect`` None), and hand the mask to the keepout
        mask server's ``load_map``; ``done(ok, text)`` runs when it answers."""
        server = self.topics.keepout_mask_server
        if not self._mask_loader.service_is_ready():
            done(False, f"no keepout mask server: {server} does not answer (eddie nav "
                        "--dashboard starts one)")
            return
        with self._cmd_lock:
            base = self._keepout_base()
        if base is None:
            done(False, "keepout: no map yet to shape the mask on")
            return
        data = np.zeros_like(base.data) if rect is None else base.data.copy()
        cells = 0
        if rect is not None:
            where = self._to_display(base.frame_id)
            if where is None:
                done(False, f"keepout: the mask frame {base.frame_id} is not placed in the "
                            f"display frame {self.display_frame} yet")
                return
            jj, ii = np.mgrid[0:base.height, 0:base.width]
            centres = map_to_world(base, np.stack([ii, jj], axis=-1))
            c, s = math.cos(where[2]), math.sin(where[2])
            dx = where[0] + c * centres[..., 0] - s * centres[..., 1]
            dy = where[1] + s * centres[..., 0] + c * centres[..., 1]
            x0, y0, x1, y1 = rect
            inside = ((dx >= min(x0, x1)) & (dx <= max(x0, x1))
                      & (dy >= min(y0, y1)) & (dy <= max(y0, y1)))
            cells = int(inside.sum())
            if cells == 0:
                done(False, "keepout: the rectangle covers no cell of the mask")
                return
            data[inside] = 100
        if self._keepout_dir is None:
            self._keepout_dir = Path(tempfile.mkdtemp(prefix="eddie_keepout_"))
        self._keepout_count += 1
        try:
            path = save_map(OccupancyMap(data, base.resolution, base.origin, base.frame_id),
                            self._keepout_dir / f"keepout_{self._keepout_count}")
        except OSError as exc:
            done(False, f"keepout: cannot write the mask: {exc}")
            return
        fut = self._mask_loader.call_async(self._mask_loader.srv_type.Request(map_url=str(path)))
        what = f"{cells} cells kept out" if rect is not None else "keepout zones cleared"

        def answered(f: Future) -> None:
            if f.exception() is not None:
                done(False, f"{server}: {f.exception()}")
                return
            code = int(f.result().result)
            done(code == 0, f"{server}: {what} ({path.name})" if code == 0
                 else f"{server}: load_map failed with result {code} ({path})")

        fut.add_done_callback(answered)
