"""Known parameters of the Mitsuba ``roughconductor`` and ``roughplastic`` models (one colour channel, inside the
ranges, away from the limits)."""

ROUGH_PARAMS = {
    "roughconductor": [0.9, 2.5, 0.2],
    "roughconductor-beckmann": [0.9, 2.5, 0.2],
    "roughplastic": [0.5, 0.15, 1.5],
}
