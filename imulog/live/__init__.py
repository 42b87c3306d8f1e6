"""Live capture from Lab Streaming Layer (LSL): record streams into a crash-safe trial, replay a trial as outlets.

* :mod:`imulog.live.lsl`: pylsl import, stream resolution by ``name=``/``type=``/``source_id=``;
* :mod:`imulog.live.mapping`: an LSL stream's XML header and samples -> the channels ``imulog convert`` makes
  for the same stream in an XDF file (one mapping: :func:`imulog.converters.xdf.stream_to_recording`);
* :mod:`imulog.live.writer`: :class:`LiveTrialWriter`, the streaming trial writer with chunks flushed every second
  into a visible ``.part`` file (a killed recorder leaves it for ``imulog salvage``);
* :mod:`imulog.live.recorder`: the recording loop (clock offsets, gaps, dropped samples, summary);
* :mod:`imulog.live.replay`: a trial's raw channels published as LSL outlets in real time;
* :mod:`imulog.live.view`: ``record --view``, the pieces sent to Rerun with VQF's online orientation.

Only :mod:`imulog.live.lsl` imports pylsl (the ``lsl`` extra), and only when a command needs it.
"""
