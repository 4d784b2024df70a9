"""MPEG-4 Face Animation: FAP/FDP tables, FAPU, the .fap reader/writer, expressions, visemes.

Imports nothing of faceforge but ``constants``/``exceptions``. Public API::

    from faceforge.mpeg4 import (FAP_TABLE, FDP_TABLE, FAPU_NAMES, LIP_PAIRS, fap_record,
                                 FapTrack, read_fap, write_fap, parse_fap, format_fap, FapWarning,
                                 Fapu, fapu_from_landmarks, fap_displacement,
                                 EXPRESSIONS, expression_track, expression_weights,
                                 VISEMES, viseme_track)
"""

from .expressions import EXPRESSION_CODES, EXPRESSIONS, expression_track, expression_weights
from .fap import FapTrack, FapWarning, format_fap, write_fap
from .fap_stream import parse_fap, read_fap
from .fapu import Fapu, fap_displacement, fapu_from_landmarks
from .visemes import VISEME_CODES, VISEMES, viseme_track
from .tables import (
    DIRECTION_VECTORS,
    FAP_BY_NAME,
    FAP_DIRECTIONS,
    FAP_TABLE,
    FAP_UNITS,
    FAPU_FORMULAS,
    FAPU_NAMES,
    FDP_BY_ID,
    FDP_IDS,
    FDP_TABLE,
    LEFT_RIGHT_PAIRS,
    LIP_PAIRS,
    N_FAPS,
    FapRecord,
    FdpRecord,
    fap_record,
)

__all__ = [
    "DIRECTION_VECTORS",
    "EXPRESSION_CODES",
    "EXPRESSIONS",
    "FAP_BY_NAME",
    "FAP_DIRECTIONS",
    "FAP_TABLE",
    "FAP_UNITS",
    "FAPU_FORMULAS",
    "FAPU_NAMES",
    "FDP_BY_ID",
    "FDP_IDS",
    "FDP_TABLE",
    "LEFT_RIGHT_PAIRS",
    "LIP_PAIRS",
    "N_FAPS",
    "VISEME_CODES",
    "VISEMES",
    "FapRecord",
    "FapTrack",
    "FapWarning",
    "Fapu",
    "FdpRecord",
    "expression_track",
    "expression_weights",
    "fap_displacement",
    "fap_record",
    "fapu_from_landmarks",
    "format_fap",
    "parse_fap",
    "read_fap",
    "viseme_track",
    "write_fap",
]
