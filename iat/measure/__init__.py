"""Measuring images and solutions: ``metrics`` (PSNR, FLIP, relative error, lit masks), ``reference``
(Mitsuba 3 path-traced references of a Scene)."""
