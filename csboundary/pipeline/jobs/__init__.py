"""The jobs behind the predicting commands, on top of the prediction and its outputs: a city
predicted into a folder of every output (prediction_run), ``predict`` and ``predict-patch`` as
library calls (predict), and the demo."""
