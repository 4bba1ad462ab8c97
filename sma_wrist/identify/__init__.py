"""Identification of the wrist's models from measured data (seed Chapter 4): ``sma-wrist identify``."""
