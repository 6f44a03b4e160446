"""Advisor for OpenAI and OpenAI-compatible servers (Ollama, vLLM, llama.cpp, transformers serve).

The API key is read from the environment only (``OPENAI_API_KEY`` by default) and handed to the
client; it is not stored on the advisor, not shown by ``repr`` and not pickled.
"""

from __future__ import annotations

import json
import logging
import os
import random
import re
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any
from urllib.parse import urlparse

import tenacity

try:  # the HTTP library the openai SDK is built on: httpx2 in its newer releases
    import httpx2 as httpx
except ImportError:  # pragma: no cover - older openai releases use httpx
    import httpx  # type: ignore[no-redef]

from pirl.advice.base import NO_ANSWER, Advisor, Answer, error_answer
from pirl.advice.parser import parse_recommendation

__all__ = ["OpenAIAdvisor"]

log = logging.getLogger(__name__)

OPENAI_URL = "https://api.openai.com/v1"
"""The server asked when neither ``base_url`` nor ``$OPENAI_BASE_URL`` names one."""
NO_KEY = "not-needed"
"""Key sent to a ``base_url`` server when the environment holds none (local servers ignore it)."""


class OpenAIAdvisor(Advisor):
    """Chat-completions advisor with timeouts, retries and bounded concurrency.

    Args:
        model: model name; for ``transformers serve`` the exact model folder path it serves.
        base_url: an OpenAI-compatible server (e.g. ``http://127.0.0.1:8000/v1``); ``None``:
            ``$OPENAI_BASE_URL`` when set (as the openai SDK does), else OpenAI itself.
        api_key_env: environment variable that holds the key. Required for OpenAI; with a
            ``base_url`` a missing key is replaced by ``"not-needed"``.
        timeout_s: per-request timeout, seconds.
        deadline_s: longest time one ``advise`` call may take, whatever the batch size,
            retries and timeouts: prompts still unanswered then fail (so a server that accepts
            connections but never answers is counted as failing instead of holding training).
        max_retries: retries after the first attempt, on rate limits (429), timeouts, dropped
            connections and server errors (5xx). Other errors are not retried.
        backoff_s: first retry delay; doubled at each retry, capped by ``max_backoff_s``, with
            up to 10% jitter. A server's ``Retry-After`` is honoured within the cap.
        max_backoff_s: longest delay between attempts.
        concurrency: requests in flight at once for a batch.
        temperature: sampling temperature (0 for the most deterministic answers).
        max_tokens: answer length limit, tokens.
        system_prompt: optional system message.
        seed: optional ``seed`` request field (best-effort determinism on OpenAI).
    """

    name = "openai"

    def __init__(
        self,
        model: str = "gpt-3.5-turbo",
        *,
        base_url: str | None = None,
        api_key_env: str = "OPENAI_API_KEY",
        timeout_s: float = 30.0,
        deadline_s: float = 60.0,
        max_retries: int = 3,
        backoff_s: float = 0.5,
        max_backoff_s: float = 8.0,
        concurrency: int = 4,
        temperature: float = 0.0,
        max_tokens: int = 64,
        system_prompt: str | None = None,
        seed: int | None = None,
    ) -> None:
        if concurrency < 1:
            raise ValueError(f"concurrency must be >= 1, got {concurrency}")
        if max_retries < 0:
            raise ValueError(f"max_retries must be >= 0, got {max_retries}")
        if timeout_s <= 0 or deadline_s <= 0:
            raise ValueError(f"timeout_s and deadline_s must be > 0, got {timeout_s}, {deadline_s}")
        self.model = model
        # The SDK reads OPENAI_BASE_URL when no base_url is given; so do the label, the cache
        # key and the key check, so that they name the server really asked.
        self.base_url = base_url or os.environ.get("OPENAI_BASE_URL") or None
        self.api_key_env = api_key_env
        self.timeout_s = float(timeout_s)
        self.deadline_s = float(deadline_s)
        self.max_retries = int(max_retries)
        self.backoff_s = float(backoff_s)
        self.max_backoff_s = float(max_backoff_s)
        self.concurrency = int(concurrency)
        self.temperature = float(temperature)
        self.max_tokens = int(max_tokens)
        self.system_prompt = system_prompt
        self.seed = seed
        host = urlparse(self.base_url).netloc if self.base_url else ""
        self.label = f"openai:{model}" + (f"@{host}" if host else "")
        self._client: Any = None
        self._client = self._make_client()  # fail early when the key is missing

    # The key lives only inside the client, which is rebuilt from the environment when needed.
    def _make_client(self) -> Any:
        import openai

        key = os.environ.get(self.api_key_env)
        if not key:
            if self.base_url is None:
                raise ValueError(
                    f"no API key: set the {self.api_key_env} environment variable "
                    "(or give base_url for a server that needs none)"
                )
            key = NO_KEY
        return openai.OpenAI(
            api_key=key,
            base_url=self.base_url,
            timeout=self.timeout_s,
            max_retries=0,
            http_client=httpx.Client(
                transport=_CappedTransport(MAX_REPLY_BYTES), timeout=self.timeout_s
            ),
        )

    @property
    def client(self) -> Any:
        """The ``openai.OpenAI`` client (created from the environment on first use)."""
        if self._client is None:
            self._client = self._make_client()
        return self._client

    def settings_key(self) -> str:
        """What changes answers besides the model: the server and the generation settings
        (not timeouts or concurrency)."""
        settings = {
            "server": (self.base_url or OPENAI_URL).rstrip("/"),
            "temperature": self.temperature,
            "max_tokens": self.max_tokens,
            "system_prompt": self.system_prompt,
            "seed": self.seed,
        }
        return json.dumps(settings, sort_keys=True)

    def advise(self, prompts: list[str], views: Sequence[Any] | None = None) -> list[Answer]:
        """Answers in prompt order, at most ``concurrency`` requests at a time; never raises."""
        if not prompts:
            return []
        try:
            client = self.client
        except Exception as exc:  # noqa: BLE001
            return [error_answer(f"{type(exc).__name__}: {exc}") for _ in prompts]
        deadline = time.monotonic() + self.deadline_s
        if len(prompts) == 1 or self.concurrency == 1:
            return [self._ask(client, p, deadline) for p in prompts]
        with ThreadPoolExecutor(max_workers=min(self.concurrency, len(prompts))) as pool:
            return list(pool.map(lambda p: self._ask(client, p, deadline), prompts))

    def _messages(self, prompt: str) -> list[dict[str, str]]:
        messages = [{"role": "user", "content": prompt}]
        if self.system_prompt is not None:
            messages.insert(0, {"role": "system", "content": self.system_prompt})
        return messages

    def _ask(self, client: Any, prompt: str, deadline: float | None = None) -> Answer:
        """One prompt, with retries (:mod:`tenacity`), done by ``deadline``
        (``time.monotonic``); every failure becomes an error answer."""
        started = time.perf_counter()
        request: dict[str, Any] = {
            "model": self.model,
            "messages": self._messages(prompt),
            "temperature": self.temperature,
            "max_tokens": self.max_tokens,
        }
        if self.seed is not None:
            request["seed"] = self.seed
        if deadline is None:
            deadline = time.monotonic() + self.deadline_s
        attempts = 0  # requests sent

        def send() -> Any:
            nonlocal attempts
            left = deadline - time.monotonic()
            if left <= 0.05:
                raise _DeadlinePassed
            attempts += 1
            # Each attempt gets what is left of the deadline at most.
            return client.chat.completions.create(**request, timeout=min(self.timeout_s, left))

        def wait(state: tenacity.RetryCallState) -> float:
            exc = state.outcome.exception() if state.outcome else None
            delay = self._delay(state.attempt_number - 1, exc or Exception())
            return min(delay, max(0.0, deadline - time.monotonic()))  # the deadline check waits

        retrying = tenacity.Retrying(
            retry=tenacity.retry_if_exception(_retryable),
            stop=tenacity.stop_after_attempt(self.max_retries + 1),
            wait=wait,
            before_sleep=_log_retry,
            reraise=True,  # the last error itself, classified below, never raised
        )
        try:
            response = retrying(send)
        except _DeadlinePassed:
            return error_answer(
                f"{NO_ANSWER} the {self.deadline_s:g} s deadline "
                f"(advisor.openai_deadline_s) after {attempts} attempt(s)",
                time.perf_counter() - started,
            )
        except Exception as exc:  # noqa: BLE001 - every failure becomes an error answer
            big = _too_large(exc)
            if big is not None:  # counted as unparseable, never kept whole
                return Answer(
                    text=big.head,
                    recommendation=None,
                    latency_s=time.perf_counter() - started,
                    reply_chars=big.size,
                )
            elapsed = time.perf_counter() - started
            return error_answer(_describe(exc, attempts, client.api_key), elapsed)
        elapsed = time.perf_counter() - started
        try:
            choice = response.choices[0]
            text = choice.message.content or ""
            usage = getattr(response, "usage", None)
            prompt_tokens = int(getattr(usage, "prompt_tokens", 0) or 0)
            completion_tokens = int(getattr(usage, "completion_tokens", 0) or 0)
        except Exception as exc:  # noqa: BLE001 - a malformed response is a failed call
            return error_answer(f"malformed response: {type(exc).__name__}: {exc}", elapsed)
        return Answer(
            text=text,
            recommendation=parse_recommendation(text),
            latency_s=elapsed,
            prompt_tokens=prompt_tokens,
            completion_tokens=completion_tokens,
        )

    def _delay(self, attempt: int, exc: Exception) -> float:
        delay = min(self.max_backoff_s, self.backoff_s * 2**attempt)
        response = getattr(exc, "response", None)
        headers = getattr(response, "headers", None)
        if headers is not None:
            try:
                retry_after = float(headers.get("retry-after", ""))
                delay = min(self.max_backoff_s, max(delay, retry_after))
            except (TypeError, ValueError):
                pass
        return delay * (1.0 + 0.1 * random.random())

    def close(self) -> None:
        """Close the HTTP client."""
        if self._client is not None:
            try:
                self._client.close()
            finally:
                self._client = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_client"] = None  # never pickle the key; rebuilt from the environment
        return state

    def __repr__(self) -> str:
        return f"OpenAIAdvisor(model={self.model!r}, base_url={self.base_url!r})"


class _DeadlinePassed(Exception):
    """Raised instead of a request when too little of the ``advise`` deadline is left."""


def _log_retry(state: tenacity.RetryCallState) -> None:
    # The error's type only: its text may echo the key (tenacity's before_sleep_log prints it).
    exc = state.outcome.exception() if state.outcome else None
    sleep = state.next_action.sleep if state.next_action else 0.0
    log.debug("retrying after %s in %.2f s", type(exc).__name__, sleep)


def _retryable(exc: BaseException) -> bool:
    """Whether a failed request may succeed later: rate limits (429), timeouts, dropped
    connections and server errors (5xx), but not a reply cut for its size."""
    import openai

    if _too_large(exc) is not None:
        return False
    return isinstance(
        exc, openai.RateLimitError | openai.APIConnectionError | openai.InternalServerError
    ) or (isinstance(exc, openai.APIStatusError) and exc.status_code >= 500)


MAX_REPLY_BYTES = 256 * 1024
"""Largest response body read from a server; the body of a longer one is cut at read time
(a chat completion of ``max_tokens`` tokens is a few kilobytes)."""
_COUNT_BEYOND = 64 * MAX_REPLY_BYTES  # how far the size of a cut body is still counted


class ReplyTooLarge(Exception):
    """A response body over :data:`MAX_REPLY_BYTES`: its head and its size (bytes, counted up
    to a bound) are kept, the rest is dropped as it arrives."""

    def __init__(self, head: str, size: int) -> None:
        super().__init__(f"reply of {size} bytes or more, over {MAX_REPLY_BYTES}")
        self.head, self.size = head, size


def _too_large(exc: BaseException | None) -> ReplyTooLarge | None:
    """The :class:`ReplyTooLarge` behind an SDK error (the SDK wraps transport errors)."""
    seen = 0
    while exc is not None and seen < 8:
        if isinstance(exc, ReplyTooLarge):
            return exc
        exc, seen = exc.__cause__ or exc.__context__, seen + 1
    return None


class _CappedStream(httpx.SyncByteStream):
    """A response body that stops at ``limit`` bytes (then raises :class:`ReplyTooLarge`)."""

    def __init__(self, inner: Any, limit: int) -> None:
        self.inner, self.limit = inner, limit

    def __iter__(self) -> Any:
        seen, head = 0, b""
        for chunk in self.inner:
            seen += len(chunk)
            if len(head) < 400:
                head += chunk[: 400 - len(head)]
            if seen > self.limit:
                for more in self.inner:
                    seen += len(more)
                    if seen > _COUNT_BEYOND:
                        break
                raise ReplyTooLarge(head.decode(errors="replace"), seen)
            yield chunk

    def close(self) -> None:
        close = getattr(self.inner, "close", None)
        if close is not None:
            close()


class _CappedTransport(httpx.HTTPTransport):
    """httpx's transport with every response body capped (:class:`_CappedStream`)."""

    def __init__(self, limit: int) -> None:
        super().__init__()
        self.limit = limit

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        response = super().handle_request(request)
        return httpx.Response(
            status_code=response.status_code,
            headers=response.headers,
            stream=_CappedStream(response.stream, self.limit),
            extensions=response.extensions,
            request=request,
        )


_KEY_LIKE = re.compile(r"\b(sk|key|token)[-_][A-Za-z0-9_\-*]{6,}", re.IGNORECASE)


def _describe(exc: Exception, attempts: int, secret: str | None = None) -> str:
    """A short error text; anything that looks like a key is masked."""
    status = getattr(exc, "status_code", None)
    kind = type(exc).__name__ + (f" {status}" if status else "")
    message = str(exc).splitlines()[0][:200] if str(exc) else ""
    if secret and secret != NO_KEY:
        message = message.replace(secret, "***")
    message = _KEY_LIKE.sub("***", message)
    return f"{kind} after {attempts} attempt(s)" + (f": {message}" if message else "")
