"""Headless Chromium (Debian's /usr/bin/chromium, which the Makefile installs) driven by
Playwright, with every request that would leave the service refused and recorded."""

from contextlib import contextmanager
from urllib.parse import urlsplit

CHROMIUM = "/usr/bin/chromium"
#: No background traffic (this machine's network is closed: Chromium would retry its hosts).
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]


class Page:
    """A browser page on one service: ``page`` (Playwright's), the URLs it asked for
    (``requested``), those refused as leaving the service (``refused``), and console errors and
    uncaught exceptions (``errors``)."""

    def __init__(self, page, base):
        self.page, self.base = page, base
        self.requested, self.refused, self.errors = [], [], []
        service = urlsplit(base).netloc
        page.on("console", lambda message: message.type == "error"
                and self.errors.append(message.text))
        page.on("pageerror", lambda error: self.errors.append(str(error)))

        def route(route):
            url = route.request.url
            self.requested.append(url)
            parts = urlsplit(url)
            if parts.scheme in ("data", "blob") or parts.netloc == service:
                route.continue_()
            else:
                self.refused.append(url)
                route.abort("blockedbyclient")

        page.route("**/*", route)


@contextmanager
def chromium(tmp_path):
    """A Playwright browser on the system's Chromium, with a fresh profile under
    ``tmp_path``; yields a function ``open(base_url) -> Page``."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            str(tmp_path / "profile"), executable_path=CHROMIUM, headless=True, args=FLAGS,
            viewport={"width": 1280, "height": 800}, device_scale_factor=1)
        try:
            def open_page(base):
                page = Page(context.new_page(), base)
                page.page.set_default_timeout(120_000)  # first renders compile kernels
                return page

            yield open_page
        finally:
            context.close()
