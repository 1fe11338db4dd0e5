"""Monopulse front end (issue 17): model and Amaranth top."""
