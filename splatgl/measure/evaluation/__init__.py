"""Scores of renders against photographs or references: metrics and dataset evaluation."""
