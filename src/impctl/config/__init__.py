"""The gateway's TOML configuration (`config.toml`, read by the daemon and the CLI): schema,
defaults, validation with one line per problem.

Every key is documented in ``deploy/config.example.toml``. Temperatures °C, durations s unless the
key says ``_h`` or ``_min``. :mod:`.sections` holds the section dataclasses and their defaults,
:mod:`.load` reads and validates the file.
"""

from .load import (
    COMFORT_BAND_MAX_K,
    LINK_LOST_LIMIT_MAX_S,
    MIN_COVERAGE_LOW,
    ConfigError,
    config_from_mapping,
    config_warnings,
    load_config,
    read_config_toml,
)
from .sections import (
    CampaignConfig,
    ClockConfig,
    Config,
    CurveConfig,
    FitConfig,
    NightConfig,
    RecordConfig,
    TargetHalfwidth,
)

__all__ = ["COMFORT_BAND_MAX_K", "LINK_LOST_LIMIT_MAX_S", "MIN_COVERAGE_LOW", "CampaignConfig",
           "ClockConfig", "Config", "ConfigError", "CurveConfig", "FitConfig", "NightConfig",
           "RecordConfig",
           "TargetHalfwidth",
           "config_from_mapping", "config_warnings", "load_config", "read_config_toml"]
