"""KD Preview's Blender glue: scene extraction, settings, operators, panel and command line.

Registration lives here; the logic lives in the modules beside it.
"""
