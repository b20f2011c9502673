"""Evaluations on real data: criteria, protocols, sequences, relations, atlases, timings."""
