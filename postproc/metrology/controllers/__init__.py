"""Compensation tables for controllers, from a parametric calibration.

One module per controller: ``linuxcnc`` (joint COMP_FILE, types 0 and 1), ``fanuc``
(bidirectional pitch error compensation), ``siemens`` ($AA_ENC_COMP part program),
``beckhoff`` (TF5280 ISG CSV component errors, also read by ``fit``). Each returns an
:class:`~postproc.metrology.controllers.base.Export`: the files, notes, and what the
controller now compensates, so that :func:`~postproc.metrology.controllers.base.remainder_dict`
can leave it out of the calibration used for program correction. The formats ``export``
offers are the entries of :data:`postproc.metrology.controllers.formats.FORMATS`.
"""
