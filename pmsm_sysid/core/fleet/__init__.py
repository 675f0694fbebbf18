"""A fleet of axes: the fleet table's columns, one recording's row, and per-axis trends of
the fitted plant parameters with drift alarms (:func:`fleet_trends`). Pure Python and numpy;
the table itself (Parquet) and the scheduling (Dask) live outside the core."""

from .columns import (
    EFFECT_PARAMS,
    MAGNITUDE,
    columns,
    diagnosis_columns,
    empty_row,
    param_columns,
    plant_columns,
    trended_parameters,
)
from .trends import (
    Alarm,
    AxisTrend,
    Observation,
    ParameterTrend,
    Point,
    TrendOptions,
    fleet_alarms,
    fleet_trends,
    robust_baseline,
    spread_factor,
)

__all__ = [
    "EFFECT_PARAMS", "MAGNITUDE", "Alarm", "AxisTrend", "Observation", "ParameterTrend",
    "Point", "TrendOptions", "columns", "diagnosis_columns", "empty_row", "fleet_alarms",
    "fleet_trends", "param_columns", "plant_columns", "robust_baseline", "spread_factor",
    "trended_parameters",
]
