"""Prepares a fresh moto server for the object-storage tests and switches it to IAM auth:
buckets `data` and `locked`, and a user `writer` allowed everything except writing or
deleting in `locked` (a bucket that denies writes). Prints {"writer": {"id", "secret"}}; from
then on only signed requests with known keys pass (wrong keys get InvalidAccessKeyId or
SignatureDoesNotMatch, as from AWS). With `--open` (`bench convert`): the buckets only, no
auth, moto's test key."""
import json
import sys
import urllib.request

import boto3

endpoint = sys.argv[1]
kw = dict(endpoint_url=endpoint, region_name="us-east-1",
          aws_access_key_id="testing", aws_secret_access_key="testing")
s3 = boto3.client("s3", **kw)
iam = boto3.client("iam", **kw)
for bucket in ["data", "locked"]:
    s3.create_bucket(Bucket=bucket)
if "--open" in sys.argv:
    print(json.dumps({"writer": {"id": "testing", "secret": "testing"}}))
    sys.exit(0)
iam.create_user(UserName="writer")
iam.put_user_policy(UserName="writer", PolicyName="lab", PolicyDocument=json.dumps({
    "Version": "2012-10-17",
    "Statement": [
        {"Effect": "Allow", "Action": "s3:*", "Resource": "*"},
        {"Effect": "Deny", "Action": ["s3:PutObject", "s3:DeleteObject"],
         "Resource": "arn:aws:s3:::locked/*"},
    ],
}))
key = iam.create_access_key(UserName="writer")["AccessKey"]
request = urllib.request.Request(endpoint + "/moto-api/reset-auth", data=b"0", method="POST",
                                 headers={"Content-Type": "text/plain"})
urllib.request.urlopen(request).read()
print(json.dumps({"writer": {"id": key["AccessKeyId"], "secret": key["SecretAccessKey"]}}))
