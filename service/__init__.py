"""raycore over HTTP: a FastAPI app that converts at its edge and calls :class:`raycore.Scene`.

Build the app with :func:`service.app.create_app`; ``raycore serve`` runs it under uvicorn.
"""
