"""Monopulse angle tracking (seed 004): array, target, IF signal, snapshot fast path."""
