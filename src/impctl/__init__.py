"""impctl: identify a house's 5R1C thermal parameters from night-time heat-pump experiments."""
