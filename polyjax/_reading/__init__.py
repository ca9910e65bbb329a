"""Bounded reading of input files: the size caps every loader checks before it reads, inflates or decodes
(``limits``), and readers of the containers several loaders share (``bounded``: files read whole, zip members
inflated in bounded chunks, ``.npz`` members checked from their headers, JSON without deep nesting or huge
integers). Every fault is a :class:`polyjax.DataFormatError` naming the file and the limit."""
