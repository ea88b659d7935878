"""Documented caps that the command line's parsers and the loaders share (import-light: the CLI reads them when it
builds its parser)."""

#: longest episode a scenario (or ``--time-limit``) may ask for [s]
MAX_TIME_LIMIT_S = 600.0
#: shortest: two control periods of Table I (an episode that ends before its first command is no episode; a
#: Gymnasium env would be over at reset) [s]
MIN_TIME_LIMIT_S = 0.1
