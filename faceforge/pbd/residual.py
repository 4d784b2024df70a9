"""Per-kind residuals ``C`` of a whole model (for tests and diagnostics)."""

from __future__ import annotations

import numpy as np

from faceforge.pbd.constraints import (
    residual_area, residual_attachment, residual_bending, residual_distance,
    residual_position, residual_volume)
from faceforge.pbd.model import Control, Model


def residuals(model: Model, positions: np.ndarray, control: Control | None = None) -> dict:
    """``{kind: (m_kind,) float64}`` constraint values C at ``positions (n, 3)``.

    Units: distance, position, attachment in length; area in length^2; volume in
    length^3; bending in radians. Position constraints use ``control.position_targets``
    (the rest targets when ``control`` is None).
    """
    m = model
    targets = m.position_rest_target if control is None else control.position_targets
    vs = m.volume_triangle_start
    return {
        "distance": residual_distance(positions, m.distance_indices, m.distance_rest_length),
        "bending": residual_bending(positions, m.bending_indices, m.bending_rest_angle),
        "area": residual_area(positions, m.area_indices, m.area_rest_area),
        "volume": np.array([residual_volume(positions, m.volume_triangles[vs[j]:vs[j + 1]],
                                            m.volume_rest_volume[j])
                            for j in range(m.volume_count)]),
        "position": residual_position(positions, m.position_indices, targets),
        "attachment": residual_attachment(positions, m.attachment_indices,
                                          m.attachment_triangles, m.attachment_bary),
    }


def max_abs_residuals(model: Model, positions: np.ndarray, control: Control | None = None) -> dict:
    """``{kind: float}`` largest ``|C|`` per kind (0 for absent kinds)."""
    return {k: float(np.abs(v).max()) if len(v) else 0.0
            for k, v in residuals(model, positions, control).items()}
