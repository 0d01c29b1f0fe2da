"""Checks that a surface_mapper PNG really carries a colour scale, by its pixels.

A height map drawn with viridis has two regions of viridis colours: the map itself and, to its
right, the colour bar: a narrow column band whose colours run through the whole scale, low at the
bottom, high at the top. A PNG without a colour bar has only the first.
"""
import numpy as np


def viridis_index(png_path):
    """Per pixel: index 0..255 of the nearest viridis colour, or -1 where the pixel is not one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image

    image = matplotlib.image.imread(png_path)[:, :, :3]
    scale = matplotlib.colormaps["viridis"](np.linspace(0.0, 1.0, 256))[:, :3]
    colours, inverse = np.unique(np.round(image.reshape(-1, 3) * 255).astype(int), axis=0, return_inverse=True)
    distance = np.linalg.norm(colours[:, None, :] / 255.0 - scale[None, :, :], axis=2)
    nearest = np.argmin(distance, axis=1)
    index = np.where(distance[np.arange(len(colours)), nearest] < 0.02, nearest, -1)
    return index[inverse.reshape(-1)].reshape(image.shape[:2])


def column_bands(index, min_fraction=0.2):
    """Runs [start, end) of columns where at least min_fraction of the pixels are viridis colours."""
    dense = (index >= 0).mean(axis=0) >= min_fraction
    bands, start = [], None
    for x, on in enumerate(list(dense) + [False]):
        if on and start is None:
            start = x
        elif not on and start is not None:
            bands.append((start, x))
            start = None
    return bands


def colour_bar_problem(png_path):
    """None when the PNG has a map and a colour bar right of it spanning the scale; else why not."""
    index = viridis_index(png_path)
    bands = column_bands(index)
    if len(bands) < 2:
        return "only %d band(s) of viridis columns %s: no colour bar next to the map" % (len(bands), bands)
    (map_start, map_end), (bar_start, bar_end) = max(bands[:-1], key=lambda b: b[1] - b[0]), bands[-1]
    width = index.shape[1]
    if not (3 <= bar_end - bar_start <= 0.1 * width and map_end - map_start >= 3 * (bar_end - bar_start)):
        return "bands %s do not look like a map and a narrow bar" % bands
    column = index[:, (bar_start + bar_end) // 2]
    values = column[column >= 0]
    if len(values) < 50:
        return "the bar is only %d pixels high" % len(values)
    if values[:5].min() < 240 or values[-5:].max() > 15:
        return "the bar does not run from the top of the scale (%d) to its bottom (%d)" % (values[0], values[-1])
    if np.mean(np.diff(values) <= 0) < 0.95:
        return "the bar's colours do not fall steadily from top to bottom"
    return None
