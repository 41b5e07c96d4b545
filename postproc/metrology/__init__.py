"""Metrology: ISO 230-2 evaluation of interferometer runs, and compensation tables
for controllers (LinuxCNC, Fanuc, Siemens, Beckhoff)."""
