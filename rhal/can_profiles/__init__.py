"""Data files of the can:// driver: the generic CiA 402 drive's EDS and the example base's DBC.

A package only so that they install with rhal (``*.eds`` and ``*.dbc`` are package data).
"""
