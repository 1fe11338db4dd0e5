"""Monopulse DSP: float golden DDC / matched filter / beams, angle equations, CRB."""
