"""Measuring images, bakes and solutions: ``metrics`` (PSNR, FLIP, relative error, lit masks), ``seams``
(radiance mismatch along shared edges), ``reference`` (Mitsuba 3 path-traced references of a Scene)."""
