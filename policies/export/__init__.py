"""Exported policies: ``quadsitl export`` (writer.py, cli.py) writes a checkpoint's policy
as ONNX (to_onnx.py) or a C header (to_c.py) with its contract (contract.py);
runtimes.py runs them back for ``quadsitl eval`` and ``quadsitl sim --autopilot``.

Nothing is imported here, so that the command line can parse ``export`` without torch.
"""
