"""How long work is run: Ctrl-C stops it at the next block boundary (:mod:`polyjax._run.interrupt`); a command-line
process ends without the interpreter's teardown (:mod:`polyjax._run.ending`)."""
