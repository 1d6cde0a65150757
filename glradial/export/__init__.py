"""Exporters: hand glradial's lens to compositing tools and graphics engines.

:mod:`~glradial.export.engines` (OpenLensIO/OpenTrackIO mm units, Unreal Engine, 3DEqualizer),
:mod:`~glradial.export.overscan` (OpenLensIO's overscan, distorting an overscanned render),
:mod:`~glradial.export.opentrackio` (OpenTrackIO samples, JSON lines / CBOR) and
:mod:`~glradial.export.opentrackio_udp` (the standard's UDP packets).
"""
