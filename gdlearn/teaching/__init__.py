"""Book support: quick mode, widgets, checked exercises, the toy estimator and the figure computations the chapters import. It imports the pipeline; nothing in the pipeline imports it."""
