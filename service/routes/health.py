"""Liveness and readiness."""

from functools import cache
from typing import Annotated

from fastapi import APIRouter, Depends
from fastapi.responses import JSONResponse

import raycore
from service.runtime import Runtime, runtime
from service.schemas import Readiness, Status

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Status, summary="The process answers")
async def healthz():
    return Status(status="ok")


@router.get("/readyz", response_model=Readiness,
            summary="Startup work (the demo scene) is done; the threading layer and threads",
            responses={503: {"model": Readiness, "description": "Still starting",
                             "content": {"application/json": {"example": {
                                 "status": "starting", "threading_layer": "tbb",
                                 "threads": 2}}}}})
async def readyz(state: Annotated[Runtime, Depends(runtime)]):
    layer, threads = _kernels()
    answer = Readiness(status="ready" if state.ready.is_set() else "starting",
                       threading_layer=layer, threads=threads)
    if state.ready.is_set():
        return answer
    return JSONResponse(answer.model_dump(), status_code=503)


@cache
def _kernels():
    """(threading layer, threads): fixed for the process once raycore is imported."""
    report = raycore.info()
    return report["threading_layer"], report["threads"]
