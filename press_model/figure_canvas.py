"""The Agg canvas every figure is drawn on: matplotlib's, with each text's size and raster made once per process.

Matplotlib 3.11's Agg renderer shapes a string again for every renderer it draws on (one per figure, and another where
a figure is measured before it is drawn) and renders it glyph by glyph in Python; text was ~40 % of a figure's
drawing. Here a string's metrics and its raster (all its glyphs in one bitmap, rendered by FreeType at once) are kept
per font, size and resolution, and a text is drawn by pasting its raster (rotated by Agg where the text is), so a tick
label or an axis label met again in the next figure costs no FreeType call. Differences against matplotlib's own
drawing: each string's raster is placed on whole pixels (matplotlib places each glyph to 1/64 pixel), so a text moves
by under half a pixel and its antialiasing differs; sizes, positions of everything else and colours are the same.

This module imports matplotlib; :mod:`press_model.plots` imports it on first use.
"""
from __future__ import annotations

import math

from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg, get_hinting_flag

CACHED = 4096  # strings kept per cache: a run's figures use a few hundred; past this the cache starts again

_metrics: dict = {}  # (text, font properties, dpi) -> (width, height, descent) in pixels
_rasters: dict = {}  # (text, font properties, dpi, antialiased) -> (bitmap, descent px, x offset px, y offset px)


def _remember(cache: dict, key, value):
    """``value`` kept in ``cache`` under ``key`` (the key's font properties copied: the caller may change its own);
    returns value."""
    if len(cache) >= CACHED:
        cache.clear()
    text, prop, *rest = key
    cache[(text, prop.copy(), *rest)] = value
    return value


class Renderer(RendererAgg):
    """RendererAgg whose texts (not mathtext) are measured and rasterised once per process (:data:`_metrics`,
    :data:`_rasters`)."""

    def get_text_width_height_descent(self, s, prop, ismath):
        """(width, height, descent) of ``s`` in pixels, as RendererAgg measures it."""
        if ismath:
            return super().get_text_width_height_descent(s, prop, ismath)
        key = (s, prop, self.dpi)
        got = _metrics.get(key)
        return got if got is not None else _remember(_metrics, key, super().get_text_width_height_descent(s, prop, ismath))

    def draw_text(self, gc, x, y, s, prop, angle, ismath=False, mtext=None):
        """Draw ``s`` with its baseline's left end at (x, y) (pixels, y downwards), rotated by ``angle`` degrees."""
        if ismath:
            return super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
        key = (s, prop, self.dpi, gc.get_antialiased())
        got = _rasters.get(key)
        if got is None:
            got = _remember(_rasters, key, self._raster(s, prop, gc.get_antialiased()))
        bitmap, descent, xo, yo = got
        # (x, y) is the baseline's start; the bitmap's bottom edge lies a descent below it, turned with the text
        rad = math.radians(angle)
        self._renderer.draw_text_image(bitmap, round(x + xo + descent * math.sin(rad)),
                                       round(y + yo + descent * math.cos(rad)) + 1, angle, gc)

    def _raster(self, s, prop, antialiased: bool):
        """(bitmap of ``s`` unrotated, uint8 coverage; its descent and its x, y offsets, pixels)."""
        font = self._prepare_font(prop)
        font.set_text(s, 0.0, flags=get_hinting_flag())
        font.draw_glyphs_to_bitmap(antialiased=antialiased)
        xo, yo = font.get_bitmap_offset()
        return font.get_image().copy(), font.get_descent() / 64.0, xo / 64.0, yo / 64.0


class Canvas(FigureCanvasAgg):
    """FigureCanvasAgg drawing with :class:`Renderer` (a new one whenever the size or dpi changes, as Agg's)."""

    def get_renderer(self):
        """The canvas's :class:`Renderer` for the figure's current size in pixels and dpi."""
        w, h = self.get_width_height(physical=True)
        key = w, h, self.figure.dpi
        if self._lastKey != key:
            self.renderer = Renderer(w, h, self.figure.dpi)
            self._lastKey = key
        return self.renderer
