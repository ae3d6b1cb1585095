"""Notebook helpers: a :class:`arshadow.frame.session.FrameResult` shows itself as its composite (``_repr_png_``);
:func:`results_sheet` tiles a list of results into one image that shows itself too.

::

    results = [session.process(cv2.imread(p), name=p) for p in paths]
    results[0]                    # in Jupyter: the composite
    results_sheet(results)        # in Jupyter: every composite, captioned, on one sheet
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from .photos import caption_panel, contact_sheet

if TYPE_CHECKING:
    from .frame.result import FrameResult

__all__ = ["Sheet", "results_sheet"]


@dataclass
class Sheet:
    """A contact sheet: ``image`` ``(H, W, 3) uint8`` BGR; shows itself as a PNG in Jupyter."""

    image: np.ndarray

    def _repr_png_(self) -> bytes:
        ok, buf = cv2.imencode(".png", self.image)
        return buf.tobytes() if ok else b""


def results_sheet(
    results: Sequence[FrameResult], *, columns: int = 4, width: int = 320, captions: bool = True
) -> Sheet:
    """One sheet of the results' composites (:func:`arshadow.photos.contact_sheet`, the package's one).

    Parameters
    ----------
    results : sequence of arshadow.frame.session.FrameResult
    columns : int
        Tiles per row (fewer when there are fewer results).
    width : int
        Tile width in pixels; the height keeps the first result's aspect ratio.
    captions : bool
        A caption bar under each tile: the input's name, the shadow mode and the total time.

    Returns
    -------
    Sheet
    """
    results = list(results)
    if not results:
        raise ValueError("results_sheet needs at least one result")
    h0, w0 = results[0].composite.shape[:2]
    height = max(1, round(width * h0 / w0))
    tiles = []
    for r in results:
        if captions:
            it = r.item
            name = Path(it.input).name if it.input else "photo"
            total = (it.timings_ms or {}).get("total")
            text = f"{name}  {it.mode or 'no shadow'}" + (f"  {total:.0f} ms" if total is not None else "")
            tiles.append(caption_panel(r.composite, text, width=width, height=height))
        else:
            tiles.append(cv2.resize(r.composite, (width, height), interpolation=cv2.INTER_AREA))
    return Sheet(contact_sheet(tiles, columns=min(columns, len(tiles)), gap=4, background=16))
