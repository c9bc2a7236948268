# DriveBench web server: non-root (uid 10001), data in the /app/var volume, health check on /api/health.
# Build: docker build -t drivebench .   (or daemonless: buildah bud --format docker -t drivebench .; README, Container)
# First start: the admin is made from a secret file (or DRIVEBENCH_ADMIN_PASSWORD) while the database has no users:
#   docker run -d -p 8000:8000 -v drivebench-var:/app/var \
#       -v ./admin_password.txt:/run/secrets/admin_password:ro \
#       -e DRIVEBENCH_ADMIN_USER=admin -e DRIVEBENCH_ADMIN_PASSWORD_FILE=/run/secrets/admin_password \
#       -e DRIVEBENCH_ALLOWED_HOSTS=drivebench.plant.example,192.168.0.10 drivebench
# (later starts leave the users alone; or make the admin by hand:
#   docker run -it --rm -v drivebench-var:/app/var drivebench users add admin --role admin)
# Buses: a socketcand gateway by address (`serve --host 0.0.0.0 --bus socketcand:GATEWAY:29536/can0`), or the
# host's SocketCAN adapters with `--network host`. deploy/compose.yaml runs it with PostgreSQL.
ARG PYTHON_IMAGE=python:3.11-slim
FROM ${PYTHON_IMAGE}
# A plant's package mirror and its CA (a file in the build context): --build-arg PIP_INDEX_URL=https://pypi.plant/simple
# --build-arg PIP_CERT=plant-ca.pem. Unset, pip asks pypi.org with the image's CAs.
ARG PIP_INDEX_URL=""
ARG PIP_CERT=""

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PATH=/opt/venv/bin:$PATH \
    DRIVEBENCH_PORT=8000

RUN groupadd --system --gid 10001 drivebench \
    && useradd --system --uid 10001 --gid drivebench --home-dir /app --no-create-home drivebench

WORKDIR /app
# The server finds templates, static files, device profiles and plant files beside the package (config.REPO_ROOT),
# so the tree is installed in place, as `make run` does, into a venv (a Debian python refuses pip system-wide).
COPY pyproject.toml README.md constraints.txt ${PIP_CERT} ./
COPY backend ./backend
COPY frontend ./frontend
COPY device_profiles ./device_profiles
COPY plants ./plants
# Production install: the server and PostgreSQL's driver at the versions of constraints.txt, no dev tools; pip is
# removed from the image afterwards (nothing installs at run time). DriveBench's own modules are compiled here: the
# server may not write beside them (and PYTHONDONTWRITEBYTECODE), so each start compiled all 300 again (issue 33).
RUN python3 -m venv /opt/venv \
    && if [ -n "$PIP_INDEX_URL" ]; then export PIP_INDEX_URL; else unset PIP_INDEX_URL; fi \
    && if [ -n "$PIP_CERT" ]; then export PIP_CERT="/app/$(basename "$PIP_CERT")"; else unset PIP_CERT; fi \
    && pip install --constraint constraints.txt --editable ".[postgresql]" \
    && python -m compileall -q backend \
    && pip uninstall --yes pip \
    && mkdir -p /app/var \
    && chown drivebench:drivebench /app/var

# Database (SQLite by default; DRIVEBENCH_DATABASE_URL=postgresql+psycopg://... for one database of several
# servers: psycopg is installed), the cookie key and uploaded profiles live here. The code stays root's.
VOLUME ["/app/var"]
USER drivebench
EXPOSE 8000

# `drivebench health` asks 127.0.0.1:$DRIVEBENCH_PORT (https when DRIVEBENCH_TLS_CERT_FILE is set).
HEALTHCHECK --interval=30s --timeout=5s --start-period=30s --retries=3 CMD ["drivebench", "health"]

# Listening on all interfaces of the container: `serve` starts only once an admin exists (made from
# DRIVEBENCH_ADMIN_PASSWORD_FILE on the first start, see above); then everyone signs in.
ENTRYPOINT ["drivebench"]
CMD ["serve", "--host", "0.0.0.0"]
