"""Multirate FMI co-simulation master for real-time simulation of controlled mechanical systems."""

__version__ = "0.1.0"
