"""Home Assistant and MQTT: discovery, live state, fit results, household commands.

Imported by the daemon only when ``[mqtt]`` is configured (``impctl.mqtt.config`` is light
and always importable).
"""
