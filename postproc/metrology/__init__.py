"""Metrology: ISO 230-2 evaluation of interferometer runs (``iso230``, with the §4.2
temperatures and the k = 2 uncertainty in ``iso230_env``), the one outlier rule that
check, fit and iso230 share (``outliers``), calibrations from runs and tables
(``tables_fit``), and compensation tables for controllers (LinuxCNC, Fanuc, Siemens,
Beckhoff), each read back before it is written (``controllers``)."""
