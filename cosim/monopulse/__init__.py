"""Monopulse angle tracking after the monopulse paper: array, target, IF signal, snapshot fast path."""
