"""Policies: failure generators for stage 1 and policies under evaluation."""
