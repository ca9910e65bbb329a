"""How long work is run: Ctrl-C stops it at the next block boundary (:mod:`polyjax._run.interrupt`)."""
