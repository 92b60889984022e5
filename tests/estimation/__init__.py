"""Tests of amsfe_sym.estimation (pure numpy/scipy; no generated code needed)."""
