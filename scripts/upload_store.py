"""Upload a store folder (a sharded store's manifest.json and shard folders) to S3-compatible storage with boto3.

    python3 scripts/upload_store.py ENDPOINT BUCKET PREFIX STORE

Creates BUCKET when it does not exist (retrying for 10 s while a just-started server comes up), then uploads every
file of STORE under PREFIX/, keeping the folder layout, so that `any4d … --data s3://BUCKET/PREFIX` reads it.
Credentials and region come from the environment, as boto3 reads them (AWS_ACCESS_KEY_ID, …). Used by the S3 store
test (data/tests/remote_store.rs) and experiments/2026-12-07-sharded-store/s3.sh against moto's local server.
"""
import os
import sys
import time

import boto3


def main():
    endpoint, bucket, prefix, root = sys.argv[1:5]
    s3 = boto3.client("s3", endpoint_url=endpoint)
    for attempt in range(100):
        try:
            s3.head_bucket(Bucket=bucket)
            break
        except Exception:
            try:
                s3.create_bucket(Bucket=bucket)
                break
            except Exception:
                if attempt == 99:
                    raise
                time.sleep(0.1)
    for folder, _, files in os.walk(root):
        for name in files:
            path = os.path.join(folder, name)
            key = prefix.strip("/") + "/" + os.path.relpath(path, root).replace(os.sep, "/")
            s3.upload_file(path, bucket, key)


if __name__ == "__main__":
    main()
