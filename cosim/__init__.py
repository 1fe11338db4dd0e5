"""The co-simulation toolkit: receivers, backends, tools.

Importing it changes nothing in the process's environment; the executables that ``make
tools`` may install into the Python environment are looked up by
:mod:`cosim.core.executables` where they are launched.
"""
