"""The impctl daemon: configuration, scheduling of IMP nights, systemd integration."""
