"""Image message ⇄ array helpers shared by the perception cores."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.perception.errors import ImageSizeError, UnsupportedEncodingError

DEPTH_ENCODINGS = ("16UC1", "32FC1")
_DTYPES: dict[str, tuple[np.dtype[Any], int]] = {
    "16UC1": (np.dtype(np.uint16), 1),
    "mono16": (np.dtype(np.uint16), 1),
    "32FC1": (np.dtype(np.float32), 1),
    "rgb8": (np.dtype(np.uint8), 3),
    "bgr8": (np.dtype(np.uint8), 3),
    "mono8": (np.dtype(np.uint8), 1),
}


def image_to_array(image: Any, accepted: tuple[str, ...] = DEPTH_ENCODINGS) -> npt.NDArray[Any]:
    """View a ``sensor_msgs/Image`` as an (H, W) or (H, W, C) array, honouring ``step``
    and ``is_bigendian``. Raises `UnsupportedEncodingError` or `ImageSizeError`."""
    encoding = str(image.encoding)
    if encoding not in accepted or encoding not in _DTYPES:
        raise UnsupportedEncodingError(
            f"image encoding {encoding!r} is not supported (accepted: {', '.join(accepted)})"
        )
    dtype, channels = _DTYPES[encoding]
    height, width, step = int(image.height), int(image.width), int(image.step)
    row_bytes = width * channels * dtype.itemsize
    data = np.asarray(image.data, dtype=np.uint8)
    if step < row_bytes or data.size < step * height:
        raise ImageSizeError(
            f"image {width}x{height} {encoding} needs step >= {row_bytes} and "
            f"{step * height} data bytes, got step {step} and {data.size} bytes"
        )
    rows = data[: step * height].reshape(height, step)[:, :row_bytes]
    stored = dtype.newbyteorder(">") if image.is_bigendian else dtype.newbyteorder("<")
    array = np.ascontiguousarray(rows).view(stored)
    shape = (height, width) if channels == 1 else (height, width, channels)
    return array.reshape(shape).astype(dtype, copy=False)


def check_size(image: Any, camera_info: Any) -> None:
    """Raise `ImageSizeError` naming both sizes when image and camera_info disagree."""
    if (int(image.width), int(image.height)) != (int(camera_info.width), int(camera_info.height)):
        raise ImageSizeError(
            f"image is {image.width}x{image.height} but camera_info is "
            f"{camera_info.width}x{camera_info.height}"
        )
