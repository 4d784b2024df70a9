"""The eyes drawn on a grey render for the detector's second look (landmarks.paint)."""

from __future__ import annotations

import numpy as np

from faceforge.landmarks.paint import (IRIS, LEFT_EYE, LID, REPAINTED, RIGHT_EYE, SCLERA, paint_eyes,
                                       polygon_mask)


def _plain_polygon_mask(polygon, shape):
    """Twin of polygon_mask: a point-in-polygon test per pixel centre (ray casting, even-odd)."""
    h, w = shape
    out = np.zeros(shape, dtype=bool)
    for r in range(h):
        for c in range(w):
            x, y, inside = c + 0.5, r + 0.5, False
            for i in range(len(polygon)):
                (x0, y0), (x1, y1) = polygon[i], polygon[(i + 1) % len(polygon)]
                if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
                    inside = not inside
            out[r, c] = inside
    return out


def test_polygon_mask_is_the_pixel_centres_inside():
    square = np.array([[2.0, 3.0], [6.0, 3.0], [6.0, 5.0], [2.0, 5.0]])
    m = polygon_mask(square, (8, 10))
    assert m.sum() == 8 and m[3:5, 2:6].all()            # columns 2-5, rows 3-4
    rng = np.random.default_rng(3)
    for _ in range(5):                                   # concave, partly off the picture
        poly = rng.uniform(-3, 17, size=(7, 2))
        assert np.array_equal(polygon_mask(poly, (14, 12)), _plain_polygon_mask(poly, (14, 12)))
    assert not polygon_mask(square + 100, (8, 10)).any()


def _face_points():
    """478 points: two eye contours as circles of radius 10 px around (80, 100) and (160, 100),
    irises at the centres, everything else at (120, 180)."""
    pts = np.tile([120.0, 180.0], (478, 1))
    for contour, centre, iris in ((LEFT_EYE, (160.0, 100.0), 473), (RIGHT_EYE, (80.0, 100.0), 468)):
        t = np.linspace(0, 2 * np.pi, len(contour), endpoint=False)
        pts[list(contour)] = np.column_stack([centre[0] + 20 * np.cos(t), centre[1] + 10 * np.sin(t)])
        pts[iris] = centre
    return pts


def test_paint_eyes_draws_opening_iris_and_lid_line_where_the_points_are():
    image = np.full((256, 256), 128, dtype=np.uint8)
    out = paint_eyes(image, _face_points())
    assert out.shape == (256, 256, 3) and out.dtype == np.uint8
    grey = out[:, :, 0]
    assert (out[:, :, 1] == grey).all()
    for cx in (80, 160):
        assert grey[100, cx] == IRIS                     # the iris at its centre
        assert grey[100, cx + 15] == SCLERA              # the opening beside it
        assert (grey[99:102, cx + 19:cx + 21] == LID).any()   # the contour (a line of 1.2 px)
        assert grey[100, cx + 25] == 128                 # the skin outside untouched
    assert grey[180, 120] == 128 and (image == 128).all()   # the rest, and the input, untouched


def test_the_second_look_replaces_the_eyes_irises_and_brows_only():
    assert {33, 133, 263, 362, 468, 473, 70, 105, 107, 300, 334, 336} <= set(REPAINTED.tolist())
    assert not {0, 13, 14, 17, 61, 152, 291, 2, 4} & set(REPAINTED.tolist())


def test_an_eye_is_open_where_the_render_sees_through_it_or_into_a_recess():
    from faceforge.landmarks.paint import eye_open

    pts = _face_points()                      # eyes 40 px wide: 0.4 mesh units at 100 px per unit
    flush = np.full((256, 256), 5.0)
    assert not eye_open(flush, pts, 100.0)
    bulge = flush.copy()
    bulge[90:111, 60:101] -= 0.05             # an eyeball standing out of the lids: still no opening
    assert not eye_open(bulge, pts, 100.0)
    socket = flush.copy()
    socket[92:109, 65:96] += 0.02             # 0.05 of the eye's width behind its contour: a socket
    assert eye_open(socket, pts, 100.0)
    shallow = flush.copy()
    shallow[92:109, 65:96] += 0.008           # 0.02 of the width: within OPEN_RECESS, flush
    assert not eye_open(shallow, pts, 100.0)
    hole = flush.copy()
    hole[95:106, 70:91] = np.inf              # the background seen through the eye
    assert eye_open(hole, pts, 100.0)
