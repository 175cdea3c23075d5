"""Files: whole-or-nothing writes (atomic), what an input path is (inputs), the output plan of a run
(outputs), and one module per file format (formats/).
"""
