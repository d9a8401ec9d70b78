"""One module or package per chapter: its demos, measurements, widgets and plots.

A chapter imports from core/, notebook/, viz/ and nodes/, never from another chapter.
"""
