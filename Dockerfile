# DriveBench web server. Build: docker build -t drivebench .
# First create an admin in the volume (the server listens on all interfaces of the container, so it refuses to
# start until someone can sign in):
#       docker run -it --rm -v drivebench-var:/app/var drivebench users add admin --role admin
# Run:  docker run -p 8000:8000 -v drivebench-var:/app/var drivebench
#       (simulated plant: append `serve --host 0.0.0.0 --demo`;
#        a socketcand gateway: `serve --host 0.0.0.0 --bus socketcand:GATEWAY:29536/can0`;
#        SocketCAN adapters of the host need `--network host`; name the address browsers use:
#        `-e DRIVEBENCH_ALLOWED_HOSTS=drivebench.plant.example,192.168.0.10`, any other Host is refused.)
#       The admin adds engineers and viewers on the Users page. The cookie key is made once in /app/var/secret_key
#       (or set DRIVEBENCH_SECRET_KEY); put TLS in front (a reverse proxy) when the network is not trusted.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    DRIVEBENCH_PORT=8000

RUN groupadd --system --gid 10001 drivebench \
    && useradd --system --uid 10001 --gid drivebench --home-dir /app --no-create-home drivebench

WORKDIR /app
# The server finds templates, static files, device profiles and plant files beside the package (config.REPO_ROOT),
# so the tree is installed in place, as `make run` does.
COPY pyproject.toml README.md ./
COPY backend ./backend
COPY frontend ./frontend
COPY device_profiles ./device_profiles
COPY plants ./plants
RUN pip install --editable ".[postgresql]" \
    && mkdir -p /app/var \
    && chown drivebench:drivebench /app/var

# Database (SQLite by default, DRIVEBENCH_DATABASE_URL=postgresql+psycopg://... for one database of several
# servers: psycopg is installed) and uploaded profiles live here.
VOLUME ["/app/var"]
USER drivebench
EXPOSE 8000

HEALTHCHECK --interval=30s --timeout=5s --start-period=30s --retries=3 \
    CMD python -c "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:' + os.environ.get('DRIVEBENCH_PORT', '8000') + '/api/health', timeout=4)"

# Listening on all interfaces of the container: `serve` starts only once an admin exists in /app/var (see above);
# then everyone signs in and each role may do only its part.
ENTRYPOINT ["drivebench"]
CMD ["serve", "--host", "0.0.0.0"]
