"""An unexpected error's 500 (issue 28 item 15) is a problem+json answer with the gate's security headers, as every
other answer: a real uvicorn server, a route that fails as a bug would."""

from __future__ import annotations

import httpx

from drivebench.web.app import create_app
from tests.conftest import serve_app
from tests.web.test_security_headers import assert_secure


def test_a_500_carries_the_security_headers_and_says_nothing_inside() -> None:
    app = create_app()

    @app.get("/api/failing")
    async def failing() -> None:
        raise RuntimeError("a secret detail of the bug")

    with serve_app(app) as url:
        answer = httpx.get(f"{url}/api/failing", timeout=30)
    assert answer.status_code == 500
    assert answer.headers["content-type"] == "application/problem+json"
    assert_secure(answer, "500")
    assert "secret detail" not in answer.text and answer.json()["status"] == 500
