"""The Identification Measurement Procedure: night plans, measured-night data, features."""
