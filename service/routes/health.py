"""Liveness and readiness."""

from typing import Annotated

from fastapi import APIRouter, Depends
from fastapi.responses import JSONResponse

from service.runtime import Runtime, runtime
from service.schemas import Status

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Status, summary="The process answers")
async def healthz():
    return Status(status="ok")


@router.get("/readyz", response_model=Status, summary="Startup work (the demo scene) is done",
            responses={503: {"model": Status, "description": "Still starting",
                             "content": {"application/json": {"example": {"status": "starting"}}}}})
async def readyz(state: Annotated[Runtime, Depends(runtime)]):
    if state.ready.is_set():
        return Status(status="ready")
    return JSONResponse({"status": "starting"}, status_code=503)
