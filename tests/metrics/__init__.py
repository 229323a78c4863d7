"""Tests of the metric plugins (``metrics/``) and their contract."""
