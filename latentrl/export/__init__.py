"""Motion out to the tools people use: the whole controller as one ONNX graph (:mod:`latentrl.export.onnx`).

Importing this package needs only torch; :func:`latentrl.export.onnx.export_command` needs the
optional ``onnx`` extra (``pip install 'latentrl[onnx]'``).
"""
