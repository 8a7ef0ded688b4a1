"""The dashboard's vSLAM graph (1 Hz) and the views a page opens: the TF tree and the
point clouds of the 3D view, converted only while a page has that view open (2 Hz at most;
the assembled map up to ``MAX_CLOUD_POINTS``, the live ``/points`` up to
``MAX_LIVE_POINTS``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from eddiebot.core.tf import TransformException
from eddiebot.viz.dashboard.core import binary_frame, text_frame
from eddiebot.viz.dashboard.display import _NS, DisplayNode, _compose, _r, _yaw

__all__ = ["MAX_CLOUD_POINTS", "MAX_LIVE_POINTS", "ViewLayers"]

#: points sent per 3D cloud (more are decimated evenly): the assembled map is sent when it
#: changes (rarely), the live sensor cloud twice a second, so it gets fewer
MAX_CLOUD_POINTS = 60000
MAX_LIVE_POINTS = 20000
#: points (or segment ends) sent per graph marker
_MAX_MARKER_POINTS = 20000
_POINT_MARKERS = {6, 7, 8}  # CUBE_LIST, SPHERE_LIST, POINTS
_LINE_MARKERS = {4, 5}  # LINE_STRIP, LINE_LIST


def _quat_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class ViewLayers(DisplayNode):
    """The vSLAM graph, the TF view and the point clouds of the 3D view."""

    #: newest graph and cloud messages with their arrival count; sent counts per name
    _clouds: dict[str, tuple[int, Any]]
    _cloud_sent: dict[str, int]

    def _on_graph(self, msg: Any) -> None:
        self._keep("graph", msg)  # sent from the status tick, at most once a second

    def _graph_frame(self, msg: Any) -> str:
        layers, nodes, loops = [], 0, 0
        for m in msg.markers:
            kind = "points" if m.type in _POINT_MARKERS else "lines" if m.type in _LINE_MARKERS else None
            if kind is None or m.action != 0:
                continue
            where = self._to_display(m.header.frame_id)
            if where is None:
                self._problems[self.topics.vslam_graph] = (
                    f"no TF from {m.header.frame_id!r} to {self.display_frame!r}")
                continue
            base = _compose(where, m.pose.position.x, m.pose.position.y, _yaw(m.pose.orientation))
            xy = np.array([(p.x, p.y) for p in m.points], np.float64).reshape(-1, 2)
            if m.type == 4 and len(xy) >= 2:  # a strip as the segments of a list
                xy = np.repeat(xy, 2, axis=0)[1:-1]
            if kind == "lines":
                xy = xy[: len(xy) // 2 * 2]
                step = max(1, -(-(len(xy) // 2) // (_MAX_MARKER_POINTS // 2)))
                xy = xy.reshape(-1, 2, 2)[::step].reshape(-1, 2)
            else:
                xy = xy[:: max(1, -(-len(xy) // _MAX_MARKER_POINTS))]
            c, s = math.cos(base[2]), math.sin(base[2])
            gx = base[0] + c * xy[:, 0] - s * xy[:, 1]
            gy = base[1] + s * xy[:, 0] + c * xy[:, 1]
            flat = np.round(np.stack([gx, gy], 1).reshape(-1), 3)
            colour = "#{:02x}{:02x}{:02x}".format(*(round(255 * min(1.0, max(0.0, v)))
                                                   for v in (m.color.r, m.color.g, m.color.b)))
            loop = "loop" in m.ns
            if kind == "points":
                nodes += len(m.points)
            elif loop:
                loops += len(m.points) // 2
            layers.append({"ns": m.ns, "kind": kind, "colour": colour, "loop": loop,
                           "pts": flat.tolist()})
        return text_frame("graph", layers=layers, nodes=nodes, loops=loops)

    def _on_cloud(self, name: str, msg: Any) -> None:
        self._keep(name, msg)  # converted only while a page has the 3D view open

    def _keep(self, name: str, msg: Any) -> None:
        seq = self._clouds[name][0] + 1 if name in self._clouds else 1
        self._clouds[name] = (seq, msg)

    def _cloud_frame(self, name: str, msg: Any) -> bytes | None:
        topic = self.topics.cloud_map if name == "cloud_map" else self.topics.points
        fields = {f.name: f for f in msg.fields}
        if any(k not in fields or int(fields[k].datatype) != 7 for k in "xyz"):  # FLOAT32
            self._problems[topic] = "point cloud without float32 x, y, z fields"
            return None
        n, step = int(msg.width) * int(msg.height), int(msg.point_step)
        buf = np.asarray(msg.data, dtype=np.uint8)
        if n and (buf.size < n * step or step < 12):
            self._problems[topic] = f"point cloud of {buf.size} bytes, expected {n * step}"
            return None
        frame = msg.header.frame_id.lstrip("/") or self.display_frame
        try:
            tr = self.tf.lookup_transform(self.display_frame, frame).transform
        except TransformException:
            self._problems[topic] = f"no TF from {frame!r} to {self.display_frame!r}"
            return None
        self._problems.pop(topic, None)
        limit = MAX_CLOUD_POINTS if name == "cloud_map" else MAX_LIVE_POINTS
        rows = buf[: n * step].reshape(n, step)[:: max(1, -(-n // limit))]
        order = ">" if msg.is_bigendian else "<"

        def column(off: int, kind: str) -> np.ndarray:
            return np.ascontiguousarray(rows[:, off: off + 4]).view(f"{order}{kind}4")[:, 0]

        xyz = np.stack([column(int(fields[k].offset), "f") for k in "xyz"], 1).astype(np.float64)
        keep = np.isfinite(xyz).all(1)
        xyz = xyz[keep]
        r = tr.rotation
        xyz = xyz @ _quat_matrix(r.x, r.y, r.z, r.w).T + (tr.translation.x, tr.translation.y,
                                                          tr.translation.z)
        colour = fields.get("rgb") or fields.get("rgba")
        rgb = b""
        if colour is not None:
            packed = column(int(colour.offset), "u")[keep] if len(rows) else np.zeros(0, np.uint32)
            rgb = np.stack([(packed >> 16) & 255, (packed >> 8) & 255, packed & 255],
                           1).astype(np.uint8).tobytes()
        return binary_frame({"t": "cloud", "name": name, "frame": self.display_frame,
                             "n": int(xyz.shape[0]), "total": n, "rgb": bool(rgb)},
                            xyz.astype(np.float32).tobytes() + rgb)

    def _tf_frame(self) -> str:
        frames = []
        for f in self.tf.all_frames():
            pose = self._to_display(f)
            if pose is not None:
                frames.append([f, _r(pose[0]), _r(pose[1]), _r(pose[2])])
        return text_frame("tf", frame=self.display_frame, frames=frames)

    def _send_views(self, now: int) -> None:
        graph = self._clouds.get("graph")
        if graph is not None and self._cloud_sent.get("graph") != graph[0] \
                and not self._throttled("graph", _NS):
            self._cloud_sent["graph"] = graph[0]
            self.hub.post("graph", self._graph_frame(graph[1]))
        if self.hub.view_open("tf"):
            self.hub.post("tf", self._tf_frame(), view="tf")
        if self.hub.view_open("cloud"):
            for name in ("cloud_map", "points"):
                kept = self._clouds.get(name)
                if kept is None or self._cloud_sent.get(name) == kept[0] \
                        or self._throttled(f"cloud:{name}", _NS // 2):
                    continue
                self._cloud_sent[name] = kept[0]
                frame = self._cloud_frame(name, kept[1])
                if frame is not None:
                    self.hub.post(f"cloud:{name}", frame, view="cloud")

    def view_changed(self, name: str, open_count: int) -> None:
        """A page opened or closed a view (server thread); a reopened cloud view is resent."""
        if name == "cloud" and open_count:
            self._cloud_sent.pop("cloud_map", None)
            self._cloud_sent.pop("points", None)
