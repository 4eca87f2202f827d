"""What several tests share: builders, closed forms and the add-on's installation. Nothing here is
a test; test modules import from here and never from one another.

``ROOT`` is the repository root (the extension's source folder)."""
import os

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
